"""The ``poise`` command line: ``poise serve``, ``poise sim`` and ``poise demo``.

Later capabilities add subcommands here (``replay``, ``bridge``); each is a
function taking the parsed arguments.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["build_parser", "main"]

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"
CONTROLLER_NAMES = ["momentum", "prioritized", "tracking"]
"""Controllers a client may pick: the keys of `controller_server.controllers.CONTROLLERS`,
listed here so that the CLI starts without importing them (a test keeps the two equal)."""


def _serve(args: argparse.Namespace) -> int:
    from controller_server.server import ControllerServer

    server = ControllerServer(
        args.bind or [DEFAULT_ENDPOINT], session_timeout_s=args.session_timeout
    )

    def request_stop(signum: int, _frame: object) -> None:
        logging.getLogger("poise.server").info("signal %d: shutting down", signum)
        server.stop_event.set()

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    print(f"poise serve: listening on {', '.join(server.bound_endpoints)}", flush=True)
    server.serve_forever()
    print("poise serve: stopped", flush=True)
    return 0


def _demo(args: argparse.Namespace) -> int:
    from clients.demo import run_demo

    return run_demo(Path(args.output), args.connect, args.backend, args.controller)


def _sim(args: argparse.Namespace) -> int:
    from clients.sim.app import SWEEP_DIRECTIONS, run_scenarios, server_endpoint, sweep_controllers
    from clients.sim.scenario import PushSpec

    overrides = {}
    if args.backend:
        overrides["backend"] = args.backend
    if args.controller:
        overrides["controller"] = args.controller
    if not args.sweep_push:
        run_scenarios(args.scenarios, Path(args.output), args.connect, overrides)
        return 0
    push = PushSpec(
        body=args.push_body,
        force_in_world_N=(1.0, 0.0, 0.0),
        start_s=args.push_start,
        duration_s=args.push_duration,
    )
    directions = SWEEP_DIRECTIONS
    if args.push_direction:
        directions = {f"({x:g}, {y:g}, {z:g})": (x, y, z) for x, y, z in args.push_direction}
    with server_endpoint(args.connect) as endpoint:
        sweep_controllers(args.scenarios[0], push, directions, endpoint, overrides)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``poise`` (also used to document the CLI)."""
    parser = argparse.ArgumentParser(
        prog="poise",
        description="Poise: whole-body balance control for bipeds, served over ZeroMQ.",
    )
    parser.add_argument(
        "--log-level",
        default="INFO",
        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
        help="logging verbosity (default: INFO)",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    serve = commands.add_parser(
        "serve",
        help="run the controller server",
        description="Serve whole-body controllers: one session per client, state in, command out.",
    )
    serve.add_argument(
        "--bind",
        action="append",
        metavar="ENDPOINT",
        help="ZeroMQ endpoint to bind, tcp:// or ipc://; repeat for several "
        f"(default: {DEFAULT_ENDPOINT}; port * picks a free one)",
    )
    serve.add_argument(
        "--session-timeout",
        type=float,
        default=30.0,
        metavar="SECONDS",
        help="drop a session after this long without a request (default: 30)",
    )
    serve.set_defaults(handler=_serve)

    sim = commands.add_parser(
        "sim",
        help="run scenarios in the simulator client against a server",
        description="Run scenarios (built-in names or TOML files) with a physics backend as a "
        "client of `poise serve`; write a JSON report and a PNG per scenario.",
    )
    sim.add_argument(
        "scenarios",
        nargs="*",
        default=["push_sequence"],
        help="scenario names or .toml paths (default: push_sequence)",
    )
    sim.add_argument("--backend", choices=["reference", "mujoco"], help="override the backend")
    sim.add_argument("--controller", choices=CONTROLLER_NAMES, help="override the controller")
    sim.add_argument("--output", default="out/sim", metavar="DIR", help="report directory")
    sim.add_argument(
        "--connect", default=None, metavar="ENDPOINT", help="use a running server at ENDPOINT"
    )
    sim.add_argument(
        "--sweep-push",
        action="store_true",
        help="find by bisection the largest push each thesis ablation and the prioritized "
        "controller survive, per direction (first scenario)",
    )
    sim.add_argument("--push-body", default="chest", help="body pushed in the sweep")
    sim.add_argument(
        "--push-direction",
        type=float,
        nargs=3,
        action="append",
        metavar=("X", "Y", "Z"),
        help="push direction in world (normalised); repeat for several (default: from behind "
        "+x, from the front -x, from the side +y)",
    )
    sim.add_argument("--push-start", type=float, default=0.5, metavar="SECONDS")
    sim.add_argument("--push-duration", type=float, default=0.1, metavar="SECONDS")
    sim.set_defaults(handler=_sim)

    demo = commands.add_parser(
        "demo",
        help="the thesis humanoid balancing under pushes in the simulator, with plots",
        description="Start `poise serve` on a free loopback port, run the thesis' push scenarios "
        "(push_sequence, head_push) in the reference simulator as its client, write "
        "DIR/report.json and DIR/<scenario>.png, print a summary. Exit code 1 if the robot fell.",
    )
    demo.add_argument(
        "--backend",
        default="reference",
        choices=["reference", "mujoco"],
        help="physics backend (default: reference)",
    )
    demo.add_argument(
        "--controller",
        default="momentum",
        choices=CONTROLLER_NAMES,
        help="controller to run (default: momentum)",
    )
    demo.add_argument(
        "--output",
        default="out",
        metavar="DIR",
        help="directory for report.json and the plots (default: out)",
    )
    demo.add_argument(
        "--connect",
        default=None,
        metavar="ENDPOINT",
        help="use a running server at ENDPOINT instead of starting one",
    )
    demo.set_defaults(handler=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``poise`` console script."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    return int(args.handler(args))


if __name__ == "__main__":
    sys.exit(main())
