"""What the ``poise`` subcommands share: constants, the one-line error, client options."""

from __future__ import annotations

import argparse
import contextlib
import math
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from clients.client import CurveKeys

__all__ = [
    "CONTROLLER_NAMES",
    "DEFAULT_ENDPOINT",
    "READY_PREFIX",
    "UsageError",
    "add_client_key_options",
    "add_run_output_options",
    "add_view_options",
    "as_usage_error",
    "check_endpoint_option",
    "curve_keys",
    "live_view",
    "non_negative",
    "positive",
    "positive_int",
    "prepare_video",
]

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"
READY_PREFIX = "poise serve: listening on "
"""First line ``poise serve`` prints, once its workers are warm and it answers at once."""
CONTROLLER_NAMES = ["momentum", "prioritized", "tracking"]
"""Controllers a client may pick: the keys of `controller_server.controllers.CONTROLLERS`,
listed here so that the CLI starts without importing them (a test keeps the two equal)."""


class UsageError(Exception):
    """A user's mistake on the command line: printed as one line, exit code 2."""


def as_usage_error(exc: Exception) -> UsageError | None:
    """The one-line error for a mistake the user can fix; ``None`` for anything else (a bug).

    Imports the error types only once something failed, so that a command
    loads only what it uses.
    """
    if isinstance(exc, UsageError):
        return exc
    from clients.bridge.actuator import BusError
    from clients.bridge.config import BridgeConfigError
    from clients.bridge.loop import BridgeStartError
    from clients.client import ServerError, ServerTimeout
    from clients.physics.errors import ScenarioError, UnsupportedModel
    from clients.pool import ClusterUnavailable
    from clients.sim.output import OutputUnusable
    from clients.visual.gl import RenderingUnavailable
    from clients.visual.live_process import LiveViewError
    from controller_server.models.description import DescriptionError
    from protocol.endpoints import InvalidEndpoint
    from protocol.errors import ErrorCode

    if isinstance(exc, ServerError) and exc.code != ErrorCode.INTERNAL:
        return UsageError(f"the server refused the request: {exc}")
    if isinstance(
        exc,
        ScenarioError
        | UnsupportedModel
        | InvalidEndpoint
        | ServerTimeout
        | ClusterUnavailable
        | OutputUnusable
        | BridgeConfigError
        | BridgeStartError
        | BusError
        | DescriptionError
        | RenderingUnavailable
        | LiveViewError,
    ):
        return UsageError(str(exc))
    return None


def positive(text: str) -> float:
    """An option's number that must be finite and above zero (a duration, a deadline)."""
    return _number(text, float, above_zero=True)


def non_negative(text: str) -> float:
    """An option's number that must be finite and at least zero (a start time, a tolerance)."""
    return _number(text, float, above_zero=False)


def positive_int(text: str) -> int:
    """An option's whole number that must be at least one (workers, a count)."""
    return int(_number(text, int, above_zero=True))


def _number(text: str, kind: type[float] | type[int], above_zero: bool) -> float:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value < 0 or (above_zero and value == 0):
        noun = "whole number" if kind is int else "finite number"
        needed = "above zero" if above_zero else "zero or more"
        raise argparse.ArgumentTypeError(f"{text} is not a {noun} {needed}")
    return value


def check_endpoint_option(option: str, endpoints: Sequence[str] | str | None) -> None:
    """Refuse an endpoint ZeroMQ cannot use (``localhost:5555``) before anything starts."""
    from protocol.endpoints import InvalidEndpoint, check_endpoint

    for endpoint in [endpoints] if isinstance(endpoints, str) else endpoints or []:
        try:
            check_endpoint(endpoint)
        except InvalidEndpoint as exc:
            raise UsageError(f"{option} {exc}") from exc


def curve_keys(args: argparse.Namespace) -> CurveKeys | None:
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


def add_client_key_options(parser: argparse.ArgumentParser) -> None:
    """``--server-key`` and ``--client-key``: CURVE for a client of a ``--connect``ed server."""
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


def add_run_output_options(parser: argparse.ArgumentParser) -> None:
    """``--record`` and ``--series``: what a simulator run writes besides its report."""
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
    parser.add_argument(
        "--video",
        action="store_true",
        help="also render each scenario to <output>/<scenario>.mp4 (MuJoCo offscreen, 30 "
        "frames per simulated second; pushes, COP, CMP, support polygon and a caption drawn "
        "in; either backend)",
    )


def add_view_options(
    parser: argparse.ArgumentParser, shows: str = "each scenario as it runs", note: str = ""
) -> None:
    """``--view`` and ``--view-port``: the live 3-D view of what ``shows`` says, and a note."""
    parser.add_argument(
        "--view",
        action="store_true",
        help=f"serve a live 3-D view of {shows} at http://127.0.0.1:PORT (robot, COP, CMP, "
        "support polygon, live plots; open it in a browser); it stops when the command ends"
        + (f". {note}" if note else ""),
    )
    parser.add_argument(
        "--view-port",
        type=int,
        default=8080,
        metavar="PORT",
        help="port of the live view (default: 8080; the next free one if taken)",
    )


@contextlib.contextmanager
def live_view(
    args: argparse.Namespace, own_process: bool = False
) -> Iterator[Callable[[Any], None] | None]:
    """With ``--view``: serve the live view and yield its run observer; else yield ``None``.

    With ``own_process``, the view runs in a child process and its observer
    never waits (for a loop with deadlines: the bridge's).
    """
    if not args.view:
        yield None
        return
    if not 1 <= args.view_port <= 65535:
        raise UsageError(f"--view-port {args.view_port}: write a TCP port, 1 to 65535")
    view: Any
    if own_process:
        from clients.visual.live_process import LiveViewProcess

        view = LiveViewProcess(port=args.view_port)
    else:
        from clients.visual.live import LiveView

        view = LiveView(port=args.view_port)
    print(f"live view: {view.url}", flush=True)
    try:
        yield view.observe
    finally:
        view.close()


def prepare_video(args: argparse.Namespace) -> None:
    """With ``--video``, choose headless OpenGL before anything imports MuJoCo."""
    if getattr(args, "video", False):
        from clients.visual.gl import choose_headless_gl

        choose_headless_gl()
