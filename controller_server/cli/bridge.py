"""``poise bridge``: drive a robot's actuators (or emulated ones) from a server."""

from __future__ import annotations

import argparse
from pathlib import Path

from controller_server.cli.common import (
    add_client_key_options,
    add_view_options,
    check_endpoint_option,
    curve_keys,
    live_view,
    non_negative,
)

__all__ = ["add_parsers"]


def _bridge(args: argparse.Namespace) -> int:
    from clients.bridge.app import format_report, run_bridge, stdin_operator, write_report
    from clients.bridge.config import load_bridge_config
    from clients.sim.app import server_endpoint

    check_endpoint_option("--connect", args.connect)
    config = load_bridge_config(args.config)
    curve = curve_keys(args)
    with live_view(args, own_process=True) as observer, server_endpoint(args.connect) as endpoint:
        run = run_bridge(
            config,
            endpoint,
            emulate=args.emulate,
            duration_s=args.duration,
            record=Path(args.record) if args.record else None,
            curve=curve,
            operator=stdin_operator(),
            observer=observer,
        )
    print(format_report(run))
    if args.report:
        write_report(run, Path(args.report))
    if run.report.stopped == "interrupted":
        return 130
    return 1 if run.report.latches or run.fall_reason else 0


def add_parsers(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``bridge``."""
    bridge = commands.add_parser(
        "bridge",
        help="drive a robot's actuators (CAN, Dynamixel) from a server",
        description="Read every actuator of the map CONFIG, send the robot state to the server, "
        "and command the torques it returns, at the map's rate, until its duration, `quit`, "
        "`estop` (typed on stdin, as is `rearm` after the safe state latched), Ctrl-C or "
        "SIGTERM (both an e-stop). Prints the loop timing and each actuator's link quality. "
        "Exit code 1 if the safe state latched or the emulated robot fell, 130 on a signal. "
        "See docs/bridge.md before connecting hardware.",
    )
    bridge.add_argument("config", metavar="CONFIG", help="actuator map (.toml, docs/bridge.md)")
    bridge.add_argument(
        "--connect",
        default=None,
        metavar="ENDPOINT",
        help="server endpoint (tcp://HOST:PORT); default: start one on a free loopback port",
    )
    bridge.add_argument(
        "--emulate",
        action="store_true",
        help="emulated actuators on a simulated robot (the map's [emulation]) instead of the "
        "configured buses: try a map without hardware",
    )
    bridge.add_argument(
        "--duration",
        type=non_negative,
        default=None,
        metavar="SECONDS",
        help="stop after this long (default: the map's duration_s; 0: until stopped)",
    )
    bridge.add_argument(
        "--record", metavar="FILE", help="record the conversation with the server (MCAP)"
    )
    bridge.add_argument("--report", metavar="FILE", help="write the run's summary as JSON")
    add_view_options(
        bridge,
        "the measured robot and the server's commands as the bridge runs",
        "A process of its own draws and serves it: the loop never waits for it",
    )
    add_client_key_options(bridge)
    bridge.set_defaults(handler=_bridge)
