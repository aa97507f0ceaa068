"""``poise replay`` and ``poise log info|plot|video``: recorded conversations."""

from __future__ import annotations

import argparse
from pathlib import Path

from controller_server.cli.common import (
    UsageError,
    add_client_key_options,
    add_view_options,
    curve_keys,
    live_view,
    non_negative,
    positive,
)

__all__ = ["EXIT_SERVER_LATE", "add_parsers"]

EXIT_SERVER_LATE = 3
"""``poise replay``'s exit code when the server did not answer in time (0 match,
1 regression, 2 a log that cannot be replayed or a usage mistake).

A log that cannot be replayed is found before a server starts: not a regular file,
not MCAP, corrupt anywhere (chunk CRCs, records, summary), a zstd bomb (chunks that
declare more than the reader's bounds), no handshake, another protocol version, or
no recorded command to compare (a replay that compares nothing is no pass)."""


def _replay(args: argparse.Namespace) -> int:
    import json
    import sys

    from clients.client import ServerError, ServerTimeout
    from clients.progress import ProgressBar
    from clients.replay import ReplayError, load_replay, replay_log
    from clients.sim.app import server_endpoint
    from protocol import ErrorCode
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
        # The whole log is read and checked before a server or a view starts.
        with ProgressBar(f"{Path(args.log).name} (reading)") as bar:
            recorded = load_replay(args.log, progress=bar)
        with (
            live_view(args) as observer,
            server_endpoint(args.connect, deadline_s=args.deadline) as endpoint,
            ProgressBar(Path(args.log).name) as bar,
        ):
            report = replay_log(
                recorded,
                endpoint,
                atol=args.atol,
                rtol=args.rtol,
                params=params,
                curve=curve_keys(args),
                realtime=args.realtime,
                progress=bar,
                observer=observer,
            )
    except (BadLog, ReplayError) as exc:
        raise UsageError(str(exc)) from None
    except (ServerTimeout, ServerError) as exc:
        if isinstance(exc, ServerError) and exc.code != ErrorCode.DEADLINE_EXCEEDED:
            raise
        # Neither a match nor a regression: the server could not answer in time.
        print(
            f"poise replay: the server did not answer in time ({exc}); on a busy machine "
            "give a longer --deadline (a server of its own) or run it again",
            file=sys.stderr,
        )
        return EXIT_SERVER_LATE
    if report.compared == 0:  # load_replay refuses such a log; never report it as a match
        raise UsageError(f"{args.log!r}: the replay compared no command: nothing was checked")
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


def _log_info(args: argparse.Namespace) -> int:
    from clients.log_info import format_summary, summarize_log
    from clients.progress import ProgressBar
    from protocol.recording import BadLog

    try:
        with ProgressBar(Path(args.log).name) as bar:
            summary = summarize_log(args.log, progress=bar)
        print(format_summary(args.log, summary))
    except BadLog as exc:
        raise UsageError(str(exc)) from None
    return 0


def _log_plot(args: argparse.Namespace) -> int:
    from clients.log_info import plot_log
    from clients.progress import ProgressBar
    from clients.replay import ReplayError
    from protocol.recording import BadLog

    for log_path in args.log:
        try:
            with ProgressBar(Path(log_path).name) as bar:
                plot_path = plot_log(log_path, args.output, progress=bar)
            print(f"{log_path}: {plot_path}")
        except (BadLog, ReplayError) as exc:
            raise UsageError(str(exc)) from None
    return 0


def _log_video(args: argparse.Namespace) -> int:
    from clients.visual.gl import choose_headless_gl

    choose_headless_gl()  # before MuJoCo is imported
    from clients.progress import ProgressBar
    from clients.replay import ReplayError
    from clients.visual.track import track_of_log
    from clients.visual.video import write_video
    from protocol.recording import BadLog

    log = Path(args.log)
    output = Path(args.output) if args.output else Path("out/logs") / f"{log.stem}.mp4"
    try:
        track = track_of_log(log)
    except (BadLog, ReplayError) as exc:
        raise UsageError(str(exc)) from None
    output.parent.mkdir(parents=True, exist_ok=True)
    with ProgressBar(f"{log.name} video") as bar:
        write_video(track, output, progress=bar)
    print(f"{log}: {output}")
    return 0


def add_parsers(commands: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Add ``replay`` and ``log``."""
    # Here, not at the top: clients.pool imports numpy, which must start after main() has
    # set single-threaded BLAS (tests/test_blas_threads.py).
    from clients.pool import BATCH_DEADLINE_S

    replay = commands.add_parser(
        "replay",
        help="replay a recorded log against a server and compare every command",
        description="Re-create the log's session from its recorded hello, send its states and "
        "set_params in order, compare each command with the recorded one (|new - old| <= "
        "atol + rtol |old| per entry). The whole log is read and checked before a server "
        "starts. Exit code 0 when every command matches, 1 on a regression, 2 on a log that "
        "cannot be replayed (corrupt, not a log, no command to compare) or a usage mistake, "
        "3 when the server could not answer in time.",
    )
    replay.add_argument("log", metavar="LOG", help="MCAP log (`poise sim --record DIR`)")
    replay.add_argument(
        "--connect", default=None, metavar="ENDPOINT", help="use a running server at ENDPOINT"
    )
    replay.add_argument(
        "--deadline",
        type=positive,
        default=BATCH_DEADLINE_S,
        metavar="S",
        help="--deadline of the server it starts (without --connect): a replay compares "
        f"commands, not their timing (default: {BATCH_DEADLINE_S:g} s, as a sweep's servers)",
    )
    replay.add_argument("--atol", type=non_negative, default=1e-9, help="absolute tolerance (1e-9)")
    replay.add_argument("--rtol", type=non_negative, default=1e-9, help="relative tolerance (1e-9)")
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
    add_view_options(
        replay,
        "the log's robot as it is replayed, with this server's commands",
        "It draws at most 30 frames a second of a replay that runs as fast as the server "
        "answers: add --realtime to watch it at the recorded pace",
    )
    add_client_key_options(replay)
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
    video = log_commands.add_parser(
        "video",
        help="an MP4 of a log's first session, rendered by MuJoCo offscreen",
        description="Render the first session of a log as `poise sim --video` renders a run: "
        "the robot in MuJoCo (the states the client sent; for IMU states, the base the server "
        "estimated), COP, CMP and support polygon on the ground, a caption; 30 frames per "
        "second of log time. Pushes are not logged, so none is drawn.",
    )
    video.add_argument("log", metavar="LOG", help="MCAP log (`poise sim --record DIR`)")
    video.add_argument(
        "-o",
        "--output",
        metavar="FILE",
        help="the MP4 to write (default: out/logs/<log name>.mp4)",
    )
    video.set_defaults(handler=_log_video)
