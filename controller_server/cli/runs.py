"""``poise sim`` and ``poise demo``: simulator runs as clients of a server."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from controller_server.cli.common import (
    CONTROLLER_NAMES,
    UsageError,
    add_client_key_options,
    add_run_output_options,
    add_view_options,
    check_endpoint_option,
    curve_keys,
    live_view,
    non_negative,
    positive,
    positive_int,
    prepare_video,
)

__all__ = ["add_parsers"]


def _sim(args: argparse.Namespace) -> int:
    if (args.video or args.view) and args.sweep_push:
        option = "--video" if args.video else "--view"
        raise UsageError(f"{option} shows scenario runs; a --sweep-push has none to show")
    if args.view and (args.dask or (args.workers or 1) > 1):
        option = "--dask" if args.dask else f"--workers {args.workers}"
        raise UsageError(f"--view shows the runs of this process, one at a time: drop {option}")
    prepare_video(args)
    from clients.physics.backend import PushSpec
    from clients.pool import RunPool, default_workers
    from clients.sim.app import run_scenarios
    from clients.sim.output import OutputDirectory
    from clients.sim.sweep import SWEEP_DIRECTIONS, sweep_controllers, sweep_entries

    overrides = {}
    if args.backend:
        overrides["backend"] = args.backend
    if args.controller and not args.sweep_push:  # a sweep picks its entries by controller
        overrides["controller"] = args.controller
    if args.base_state:
        overrides["base_state"] = args.base_state
    if args.model:
        overrides["model"] = args.model
    if args.keyframe:
        overrides["keyframe"] = args.keyframe
    if args.duration is not None:
        overrides["duration_s"] = args.duration
    if args.contacts:
        overrides["contacts"] = [{"name": frame, "frame": frame} for frame in args.contacts]
    check_endpoint_option("--connect", args.connect)
    curve = curve_keys(args)
    workers = default_workers() if args.workers is None else args.workers
    if not args.sweep_push:
        record_dir = Path(args.record) if args.record else None
        with live_view(args) as observer:
            reports = run_scenarios(
                args.scenarios,
                Path(args.output),
                args.connect,
                overrides,
                curve=curve,
                record_dir=record_dir,
                series=args.series,
                video=args.video,
                observer=observer,
                workers=1 if args.view else workers,
                dask=args.dask,
            )
        return 1 if any(report["fell"] or not report["complete"] for report in reports) else 0
    push = PushSpec(
        body=args.push_body,
        force_in_world_N=(1.0, 0.0, 0.0),
        start_s=args.push_start,
        duration_s=args.push_duration,
    )
    directions = SWEEP_DIRECTIONS
    if args.push_direction:
        for x, y, z in args.push_direction:
            if not math.isfinite(x * x + y * y + z * z) or x * x + y * y < 1e-12:
                raise UsageError(
                    f"--push-direction {x:g} {y:g} {z:g}: give a direction with a horizontal "
                    "part (finite numbers), e.g. 1 0 0 from behind"
                )
        directions = {f"({x:g}, {y:g}, {z:g})": (x, y, z) for x, y, z in args.push_direction}
    output_dir = Path(args.output)
    controllers = sweep_entries(args.controller)
    pairs = len(controllers) * len(directions)  # no more workers than bisections
    with (
        OutputDirectory(output_dir),
        RunPool(min(workers, pairs), args.dask, args.connect, curve) as pool,
    ):
        sweep_controllers(
            args.scenarios[0],
            push,
            directions,
            pool,
            overrides,
            output_dir=output_dir,
            controllers=controllers,
        )
    return 0


def _demo(args: argparse.Namespace) -> int:
    prepare_video(args)
    from clients.demo import run_demo

    check_endpoint_option("--connect", args.connect)
    with live_view(args) as observer:
        return run_demo(
            Path(args.output),
            args.connect,
            args.backend,
            args.controller,
            curve=curve_keys(args),
            record_dir=Path(args.record) if args.record else None,
            series=args.series,
            video=args.video,
            observer=observer,
        )


def add_parsers(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``sim`` and ``demo``."""
    sim = commands.add_parser(
        "sim",
        help="run scenarios in the simulator client against a server",
        description="Run scenarios (built-in names, see `poise list scenarios`, or TOML files) "
        "with a physics backend as a client of `poise serve` (started on a free loopback port "
        "unless --connect); write DIR/report.json and DIR/<scenario>.png, print a summary. "
        "Exit code 1 if the robot fell in any scenario.",
    )
    sim.add_argument(
        "scenarios",
        nargs="*",
        default=["push_sequence"],
        help="scenario names or .toml paths (default: push_sequence)",
    )
    sim.add_argument(
        "--backend",
        choices=["reference", "mujoco"],
        help="physics backend for every scenario (default: each scenario's own)",
    )
    sim.add_argument(
        "--controller",
        choices=CONTROLLER_NAMES,
        help="controller for every scenario (default: each scenario's own); with --sweep-push, "
        "sweep only this controller (momentum: the full controller, not its ablations)",
    )
    sim.add_argument(
        "--base-state",
        choices=["truth", "imu"],
        help="how the base reaches the server for every scenario: the simulator's truth, or a "
        "simulated IMU's readings that the server estimates it from (default: each "
        "scenario's own)",
    )
    sim.add_argument(
        "--model",
        metavar="MODEL",
        help="robot for every scenario: a built-in name, or an MJCF (a scene with includes is "
        "fine) or URDF file (default: each scenario's own; see `poise inspect MODEL`)",
    )
    sim.add_argument(
        "--keyframe",
        metavar="NAME",
        help="MJCF keyframe of the standing pose for every scenario: initial pose, reference "
        "pose and CM height (default: each scenario's own)",
    )
    sim.add_argument(
        "--duration",
        type=positive,
        metavar="SECONDS",
        help="simulated time of every scenario (default: each scenario's own; a sweep's "
        "trials last at least 3 s past their push)",
    )
    sim.add_argument(
        "--contacts",
        nargs="+",
        metavar="FRAME",
        help="the feet's bodies (or sites) for every scenario, soles found from their collision "
        "geometry (default: each scenario's own, else found automatically)",
    )
    sim.add_argument(
        "--output",
        default="out/sim",
        metavar="DIR",
        help="directory for report.json and the plots (default: out/sim)",
    )
    sim.add_argument(
        "--connect",
        default=None,
        metavar="ENDPOINT",
        help="use a running server at ENDPOINT (tcp://HOST:PORT) instead of starting one",
    )
    sim.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        metavar="N",
        help="run the sweep's bisections, or the scenarios, on N local worker processes "
        "sharing one server (default: one per core, no more than there are bisections or "
        "scenarios; 1: one by one in this process, a scenario's progress bar moving with its "
        "ticks); the same results for any N",
    )
    sim.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="run them on the Dask cluster whose scheduler is at ADDRESS (tcp://HOST:8786; "
        "needs `pip install 'poise[dask]'`): against the --connect server if given (it must "
        "be reachable from the Dask workers), else each Dask worker starts its own",
    )
    sim.add_argument(
        "--sweep-push",
        action="store_true",
        help="find by bisection the largest push each thesis ablation and the prioritized "
        "controller (or only --controller) survive, per direction (first scenario); prints a "
        "table with the impulse survived as a share of the robot's no-step bound (m ω d: "
        "mass, √(g/CM height), CM to the soles' edge along the push), writes "
        "DIR/sweep_<scenario>.json (every trial) and DIR/sweep_<scenario>.png (survived/fell "
        "over direction and force, a polar plot per controller)",
    )
    sim.add_argument(
        "--push-body",
        default="chest",
        metavar="BODY",
        help="body pushed in the sweep; `trunk` is the robot's heaviest segment outside the "
        "legs, `root` its root body (default: chest, or the trunk on a robot without one; see "
        "`poise list bodies MODEL`)",
    )
    sim.add_argument(
        "--push-direction",
        type=float,
        nargs=3,
        action="append",
        metavar=("X", "Y", "Z"),
        help="push direction in world (normalised); repeat for several (default: from behind "
        "+x, from the front -x, from the side +y)",
    )
    sim.add_argument(
        "--push-start",
        type=non_negative,
        default=0.5,
        metavar="SECONDS",
        help="when the swept push starts, in simulated time (default: 0.5)",
    )
    sim.add_argument(
        "--push-duration",
        type=positive,
        default=0.1,
        metavar="SECONDS",
        help="how long the swept push lasts (default: 0.1)",
    )
    add_client_key_options(sim)
    add_run_output_options(sim)
    add_view_options(sim)
    sim.set_defaults(handler=_sim)

    demo = commands.add_parser(
        "demo",
        help="the thesis humanoid balancing under pushes in the simulator, with plots",
        description="Start `poise serve` on a free loopback port (or use --connect), run the "
        "thesis' push scenarios (push_sequence, head_push) in the simulator (--backend) as its "
        "client, write DIR/report.json and DIR/<scenario>.png, print a summary. Exit code 1 if "
        "the robot fell.",
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
    add_client_key_options(demo)
    add_run_output_options(demo)
    add_view_options(demo)
    demo.set_defaults(handler=_demo)
