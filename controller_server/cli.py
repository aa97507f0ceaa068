"""The ``poise`` command line: ``poise serve``, ``poise sim``, ``poise demo``, ``poise list``, ….

Later capabilities add subcommands here (``bridge``); each is a function
taking the parsed arguments. A mistake the user can fix (a scenario, an
endpoint, no server answering) is one line on stderr and exit code 2;
``poise --debug`` shows its traceback instead. The module imports nothing
heavy, so that :func:`main` sets single-threaded BLAS before numpy loads.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from controller_server.blas import default_to_single_threaded_blas

if TYPE_CHECKING:
    from clients.client import CurveKeys
    from controller_server.config import ServeConfig

__all__ = ["build_parser", "main"]

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"
READY_PREFIX = "poise serve: listening on "
"""First line ``poise serve`` prints, once its workers are warm and it answers at once."""
CONTROLLER_NAMES = ["momentum", "prioritized", "tracking"]
"""Controllers a client may pick: the keys of `controller_server.controllers.CONTROLLERS`,
listed here so that the CLI starts without importing them (a test keeps the two equal)."""


class UsageError(Exception):
    """A user's mistake on the command line: printed as one line, exit code 2."""


def _as_usage_error(exc: Exception) -> UsageError | None:
    """The one-line error for a mistake the user can fix; ``None`` for anything else (a bug).

    Imports the error types only once something failed, so that a command
    loads only what it uses.
    """
    if isinstance(exc, UsageError):
        return exc
    from clients.client import ServerTimeout
    from clients.sim.errors import ScenarioError
    from clients.sim.output import OutputBusy
    from protocol.endpoints import InvalidEndpoint

    if isinstance(exc, ScenarioError | InvalidEndpoint | ServerTimeout | OutputBusy):
        return UsageError(str(exc))
    return None


def _check_endpoint_option(option: str, endpoints: Sequence[str] | str | None) -> None:
    """Refuse an endpoint ZeroMQ cannot use (``localhost:5555``) before anything starts."""
    from protocol.endpoints import InvalidEndpoint, check_endpoint

    for endpoint in [endpoints] if isinstance(endpoints, str) else endpoints or []:
        try:
            check_endpoint(endpoint)
        except InvalidEndpoint as exc:
            raise UsageError(f"{option} {exc}") from exc


def _serve_config(args: argparse.Namespace) -> ServeConfig:
    from controller_server.config import ServeConfig

    return ServeConfig(
        endpoints=tuple(args.bind or [DEFAULT_ENDPOINT]),
        workers=args.workers,
        session_timeout_s=args.session_timeout,
        deadline_s=args.deadline,
        hello_deadline_s=args.hello_deadline,
        recycle_after_s=args.recycle_after,
        max_sessions=args.max_sessions,
        max_sessions_per_client=args.max_sessions_per_client,
        max_in_flight=args.max_in_flight,
        max_message_bytes=args.max_message_bytes,
        max_model_bytes=args.max_model_bytes,
        model_cache_entries=args.model_cache,
        model_dirs=tuple(str(Path(d).resolve()) for d in args.model_dir or []),
        curve_secret_key=args.curve_secret_key,
        allow_client_keys=args.allow_client_keys,
        stats_all=args.stats_all,
        record_dir=str(Path(args.record).resolve()) if args.record else None,
        log_level=args.log_level,
    )


def _serve(args: argparse.Namespace) -> int:
    from controller_server.server import ControllerServer, ServerStartError

    _check_endpoint_option("--bind", args.bind)
    try:
        config = _serve_config(args)
        for directory in config.model_dirs:
            if not Path(directory).is_dir():
                raise ValueError(f"--model-dir {directory!r} is not a directory")
        if config.record_dir is not None:
            _make_record_dir(Path(config.record_dir))
        server = ControllerServer(config)
    except (ValueError, ServerStartError) as exc:
        print(f"poise serve: {exc}", file=sys.stderr)
        return 2

    def request_stop(signum: int, _frame: object) -> None:
        logging.getLogger("poise.server").info("signal %d: shutting down", signum)
        server.stop_event.set()

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    try:
        server.start_workers()
    except ServerStartError as exc:
        server.close()
        print(f"poise serve: {exc}", file=sys.stderr)
        return 2
    if server.stop_event.is_set():
        server.close()
        return 0
    if not config.curve_secret_key and not all(_is_loopback(e) for e in server.bound_endpoints):
        logging.getLogger("poise.server").warning(
            "serving without CURVE on a non-loopback endpoint: anyone who reaches it can "
            "drive the robot; see the README's security section"
        )
    print(f"{READY_PREFIX}{', '.join(server.bound_endpoints)}", flush=True)
    server.serve_forever()
    print("poise serve: stopped", flush=True)
    return 0


def _make_record_dir(directory: Path) -> None:
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--record {str(directory)!r}: {exc.strerror or exc}") from None
    if not os.access(directory, os.W_OK):
        raise ValueError(f"--record {str(directory)!r} is not writable")


def _is_loopback(endpoint: str) -> bool:
    if endpoint.startswith(("ipc://", "inproc://")):
        return True
    host = endpoint.split("://", 1)[-1].rsplit(":", 1)[0].strip("[]")
    return host in ("localhost", "::1") or host.startswith("127.")


def _keygen(args: argparse.Namespace) -> int:
    import zmq.auth

    directory = Path(args.directory)
    directory.mkdir(parents=True, exist_ok=True)
    public, secret = directory / f"{args.name}.key", directory / f"{args.name}.key_secret"
    if public.exists() or secret.exists():
        print(f"poise keygen: {public} or {secret} exists; choose another --name", file=sys.stderr)
        return 2
    zmq.auth.create_certificates(str(directory), args.name)
    secret.chmod(0o600)
    print(f"public key: {public}\nsecret key: {secret}")
    return 0


def _curve_keys(args: argparse.Namespace) -> CurveKeys | None:
    """The client's CURVE keys from ``--server-key``/``--client-key``, if given."""
    from clients.client import CurveKeys

    if args.server_key is None:
        if args.client_key is not None:
            raise UsageError("--client-key needs --server-key (the server's public key file)")
        return None
    try:
        return CurveKeys.from_files(args.server_key, args.client_key)
    except ValueError as exc:  # InvalidKeyFile: one line naming the file
        raise UsageError(str(exc)) from None


def _demo(args: argparse.Namespace) -> int:
    from clients.demo import run_demo

    _check_endpoint_option("--connect", args.connect)
    return run_demo(
        Path(args.output),
        args.connect,
        args.backend,
        args.controller,
        curve=_curve_keys(args),
        record_dir=Path(args.record) if args.record else None,
        series=args.series,
    )


def _log_info(args: argparse.Namespace) -> int:
    from clients.log_info import format_summary, summarize_log
    from protocol.recording import BadLog

    try:
        print(format_summary(args.log, summarize_log(args.log)))
    except BadLog as exc:
        raise UsageError(str(exc)) from None
    return 0


def _log_plot(args: argparse.Namespace) -> int:
    from clients.log_info import plot_log
    from clients.replay import ReplayError
    from protocol.recording import BadLog

    for log_path in args.log:
        try:
            print(f"{log_path}: {plot_log(log_path, args.output)}")
        except (BadLog, ReplayError) as exc:
            raise UsageError(str(exc)) from None
    return 0


def _replay(args: argparse.Namespace) -> int:
    import json

    from clients.progress import ProgressBar
    from clients.replay import ReplayError, replay_log
    from clients.sim.app import server_endpoint
    from protocol.recording import BadLog

    params = {}
    for assignment in args.set or []:
        name, _, value = assignment.partition("=")
        if not name or not _:
            raise UsageError(f"--set {assignment!r}: write NAME=VALUE (VALUE in JSON)")
        try:
            params[name] = json.loads(value)
        except json.JSONDecodeError:
            params[name] = value  # a bare word: a text parameter
    try:
        with server_endpoint(args.connect) as endpoint, ProgressBar(Path(args.log).name) as bar:
            report = replay_log(
                args.log,
                endpoint,
                atol=args.atol,
                rtol=args.rtol,
                params=params,
                curve=_curve_keys(args),
                realtime=args.realtime,
                progress=bar,
            )
    except (BadLog, ReplayError) as exc:
        raise UsageError(str(exc)) from None
    if report.log_truncated:
        print(
            f"warning: the log ends early (its recorder was killed?): replayed the "
            f"{report.messages_read} messages before the cut"
        )
    print(
        f"sent {report.requests_sent} requests, compared {report.compared} commands; "
        f"max abs error {report.max_abs_error:.3g}, "
        f"max rel error {report.max_rel_error:.3g} (atol {args.atol:g}, rtol {args.rtol:g})"
    )
    if report.regression:
        print(
            f"REGRESSION: {report.divergent_commands} commands out of tolerance; first at seq "
            f"{report.first_divergent_seq}: {', '.join(report.divergent_fields)}"
        )
    else:
        print("replay matches the recording")
    if args.json:
        Path(args.json).write_text(json.dumps(report.to_json(), indent=2))
    return 1 if report.regression else 0


def _sim(args: argparse.Namespace) -> int:
    from clients.sim.app import SWEEP_DIRECTIONS, run_scenarios, server_endpoint, sweep_controllers
    from clients.sim.scenario import PushSpec

    overrides = {}
    if args.backend:
        overrides["backend"] = args.backend
    if args.controller:
        overrides["controller"] = args.controller
    _check_endpoint_option("--connect", args.connect)
    curve = _curve_keys(args)
    if not args.sweep_push:
        record_dir = Path(args.record) if args.record else None
        reports = run_scenarios(
            args.scenarios,
            Path(args.output),
            args.connect,
            overrides,
            curve=curve,
            record_dir=record_dir,
            series=args.series,
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
        directions = {f"({x:g}, {y:g}, {z:g})": (x, y, z) for x, y, z in args.push_direction}
    with server_endpoint(args.connect) as endpoint:
        sweep_controllers(args.scenarios[0], push, directions, endpoint, overrides, curve=curve)
    return 0


LIST_WHAT = ["scenarios", "models", "controllers", "joints", "bodies"]
"""What ``poise list`` lists; ``joints`` and ``bodies`` of one model."""


def _list(args: argparse.Namespace) -> int:
    """Print one line per item: scenarios, models, controllers, or a model's joints or bodies."""
    if args.what in ("joints", "bodies") and args.model is None:
        raise UsageError(f"name the model: poise list {args.what} MODEL (poise list models)")
    if args.what not in ("joints", "bodies") and args.model is not None:
        raise UsageError(f"poise list {args.what} takes no MODEL")
    for line in _list_lines(args.what, args.model):
        print(line)
    return 0


def _list_lines(what: str, model: str | None) -> list[str]:
    if what == "scenarios":
        from clients.sim.scenario import builtin_scenario_names, load_scenario

        lines = []
        for name in builtin_scenario_names():
            description = " ".join(load_scenario(name).description.split())
            if len(description) > 80:
                description = description[:79] + "…"
            lines.append(f"{name:<26}{description}".rstrip())
        return lines
    if what == "models":
        from clients.sim.model_file import builtin_model_names

        return builtin_model_names()
    if what == "controllers":
        return [f"{name}{'  (default)' if name == 'momentum' else ''}" for name in CONTROLLER_NAMES]
    from clients.sim.model_file import body_names, resolve_model_path

    try:
        path = resolve_model_path(str(model))
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from exc
    if what == "bodies":
        return body_names(path)
    from controller_server.errors import ModelError
    from controller_server.models import load_robot_model

    try:
        robot = load_robot_model(
            model_text=path.read_text(),
            model_format="urdf" if path.suffix.lower() == ".urdf" else "mjcf",
        )
    except ModelError as exc:
        raise UsageError(f"{model}: {exc}") from exc
    # One line per joint in wire order, with what initial_joint_position takes for it.
    return [
        f"{joint.name:<26}{joint.kind:<11}"
        + ("4 numbers, a quaternion [x, y, z, w]" if joint.kind == "ball" else f"{joint.nq} number")
        for joint in robot.joints
    ]


def _add_client_key_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--server-key",
        metavar="FILE",
        help="with --connect to a CURVE server: its public key file (NAME.key of `poise keygen`)",
    )
    parser.add_argument(
        "--client-key",
        metavar="FILE",
        help="this client's secret key file (NAME.key_secret); default: a throwaway key pair",
    )


def _add_run_output_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--record",
        metavar="DIR",
        help="record each scenario's conversation with the server to DIR/<scenario>.mcap",
    )
    parser.add_argument(
        "--series",
        action="store_true",
        help="also write each scenario's raw time series (states, commands, diagnostics) "
        "to <output>/<scenario>.npz",
    )


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
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the traceback of an error instead of its one-line message",
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
    serve.add_argument(
        "--workers",
        type=int,
        default=max(1, os.cpu_count() or 1),
        metavar="N",
        help="worker processes serving the sessions (default: one per core)",
    )
    serve.add_argument(
        "--deadline",
        type=float,
        default=0.5,
        metavar="SECONDS",
        help="answer a state, set_params or bye within this time of receipt, else with "
        "DEADLINE_EXCEEDED (default: 0.5)",
    )
    serve.add_argument(
        "--hello-deadline",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="the same for hello: model load and controller creation (default: 10)",
    )
    serve.add_argument(
        "--recycle-after",
        type=float,
        default=5.0,
        metavar="SECONDS",
        help="a worker still busy this long past a request's deadline is killed and replaced, "
        "losing its sessions (default: 5)",
    )
    serve.add_argument(
        "--max-sessions",
        type=int,
        default=128,
        metavar="N",
        help="sessions on the server (default: 128)",
    )
    serve.add_argument(
        "--max-sessions-per-client",
        type=int,
        default=32,
        metavar="N",
        help="sessions per client: per CURVE key, or per peer address (default: 32)",
    )
    serve.add_argument(
        "--max-in-flight",
        type=int,
        default=2,
        metavar="N",
        help="requests of one session being served at once; more are refused (default: 2)",
    )
    serve.add_argument(
        "--max-message-bytes",
        type=int,
        default=16 * 1024 * 1024,
        metavar="BYTES",
        help="largest request answered (default: 16 MiB)",
    )
    serve.add_argument(
        "--max-model-bytes",
        type=int,
        default=4 * 1024 * 1024,
        metavar="BYTES",
        help="largest model text or model/clip file (default: 4 MiB)",
    )
    serve.add_argument(
        "--model-cache",
        type=int,
        default=16,
        metavar="N",
        help="parsed models each worker keeps (default: 16)",
    )
    serve.add_argument(
        "--model-dir",
        action="append",
        metavar="DIR",
        help="directory whose model and clip files clients may name; repeatable "
        "(default: built-in models and clips only)",
    )
    serve.add_argument(
        "--curve-secret-key",
        metavar="FILE",
        help="encrypt and authenticate with CurveZMQ using this server secret key "
        "(`poise keygen`); needed on anything but loopback",
    )
    serve.add_argument(
        "--allow-client-keys",
        metavar="DIR",
        help="with CURVE: only clients whose public key file is in DIR (default: any key)",
    )
    serve.add_argument(
        "--stats-all",
        action="store_true",
        help="stats lists every session (default: only the asking client's own)",
    )
    serve.add_argument(
        "--record",
        metavar="DIR",
        help="record every session's conversation to DIR/<UTC time>-<session id>.mcap "
        "(created if missing; `poise replay` replays a file)",
    )
    serve.set_defaults(handler=_serve)

    keygen = commands.add_parser(
        "keygen",
        help="make a CurveZMQ key pair for `poise serve --curve-secret-key` or a client",
        description="Write NAME.key (public, give it to the other side) and NAME.key_secret "
        "(secret, keep it) in DIRECTORY.",
    )
    keygen.add_argument("directory", metavar="DIRECTORY")
    keygen.add_argument("--name", default="server", help="file name stem (default: server)")
    keygen.set_defaults(handler=_keygen)

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
        help="controller for every scenario (default: each scenario's own)",
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
        "--sweep-push",
        action="store_true",
        help="find by bisection the largest push each thesis ablation and the prioritized "
        "controller survive, per direction (first scenario)",
    )
    sim.add_argument(
        "--push-body",
        default="chest",
        metavar="BODY",
        help="body pushed in the sweep (default: chest; see `poise list bodies MODEL`)",
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
        type=float,
        default=0.5,
        metavar="SECONDS",
        help="when the swept push starts, in simulated time (default: 0.5)",
    )
    sim.add_argument(
        "--push-duration",
        type=float,
        default=0.1,
        metavar="SECONDS",
        help="how long the swept push lasts (default: 0.1)",
    )
    _add_client_key_options(sim)
    _add_run_output_options(sim)
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
    _add_client_key_options(demo)
    _add_run_output_options(demo)
    demo.set_defaults(handler=_demo)

    replay = commands.add_parser(
        "replay",
        help="replay a recorded log against a server and compare every command",
        description="Re-create the log's session from its recorded hello, send its states and "
        "set_params in order, compare each command with the recorded one (|new - old| <= "
        "atol + rtol |old| per entry). Exit code 1 on a regression, 2 on a log that cannot be "
        "replayed.",
    )
    replay.add_argument("log", metavar="LOG", help="MCAP log (`poise sim --record DIR`)")
    replay.add_argument(
        "--connect", default=None, metavar="ENDPOINT", help="use a running server at ENDPOINT"
    )
    replay.add_argument("--atol", type=float, default=1e-9, help="absolute tolerance (1e-9)")
    replay.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance (1e-9)")
    replay.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="override a parameter of the recorded hello (VALUE in JSON); repeatable",
    )
    replay.add_argument(
        "--realtime",
        action="store_true",
        help="send each state at its recorded time (default: as fast as the server answers)",
    )
    replay.add_argument("--json", metavar="REPORT", help="also write the report as JSON")
    _add_client_key_options(replay)
    replay.set_defaults(handler=_replay)

    log_command = commands.add_parser(
        "log", help="inspect a recorded log", description="Inspect a recorded MCAP log."
    )
    log_commands = log_command.add_subparsers(dest="log_command", required=True, metavar="WHAT")
    info = log_commands.add_parser(
        "info",
        help="sessions, model, controller, parameters, duration, message counts and rates",
        description="Summarize a recorded log: sessions (model, hash, controller, parameters), "
        "duration, messages per type and direction, states per second.",
    )
    info.add_argument("log", metavar="LOG")
    info.set_defaults(handler=_log_info)
    plot = log_commands.add_parser(
        "plot",
        help="the simulator's PNG plot of a log's first session",
        description="Plot the first session of each log as `poise sim` plots a run (ground "
        "reference points, CM height, momenta, joint torques) to DIR/<log name>.png.",
    )
    plot.add_argument("log", metavar="LOG", nargs="+")
    plot.add_argument(
        "--output",
        default="out/logs",
        metavar="DIR",
        help="directory for the plots (default: out/logs)",
    )
    plot.set_defaults(handler=_log_plot)

    listing = commands.add_parser(
        "list",
        help="list built-in scenarios, models, controllers, or a model's joints or bodies",
        description="Print one line per item: the built-in scenarios (with their description), "
        "models and controllers; the joints of MODEL in wire order (with the numbers "
        "initial_joint_position takes for each), or the bodies of MODEL (what a push may name). "
        "MODEL is a built-in name or an .xml/.urdf file.",
    )
    listing.add_argument("what", choices=LIST_WHAT, metavar="{" + ",".join(LIST_WHAT) + "}")
    listing.add_argument("model", nargs="?", metavar="MODEL", help="for joints and bodies")
    listing.set_defaults(handler=_list)
    return parser


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``poise`` console script.

    Sets single-threaded BLAS (unless the environment says otherwise) before
    anything imports numpy; turns a user's mistake into one line on stderr
    and exit code 2 (``--debug``: the traceback). SIGTERM stops a command as
    Ctrl-C does (``poise serve`` installs its own handlers): what ran is kept
    (a partial report), exit code 130.
    """
    default_to_single_threaded_blas()
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        return int(args.handler(args))
    except KeyboardInterrupt:
        print(f"poise {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        mistake = _as_usage_error(exc)
        if mistake is None or args.debug:
            raise
        print(f"poise {args.command}: {mistake}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
