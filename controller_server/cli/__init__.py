"""The ``poise`` command line: ``poise serve``, ``sim``, ``demo``, ``list``, ``inspect``, ….

One module per group of subcommands (``serve``, ``runs``, ``logs``,
``listing``, ``inspect``), each adding its parsers; a handler takes the parsed
arguments. A mistake the user can fix (a scenario, an endpoint, no server
answering) is one line on stderr and exit code 2;
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
from typing import NoReturn

from controller_server.blas import default_to_single_threaded_blas
from controller_server.cli import bridge, inspect, listing, logs, runs, serve
from controller_server.cli.common import CONTROLLER_NAMES, UsageError, as_usage_error

__all__ = ["CONTROLLER_NAMES", "UsageError", "build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    """An argument parser whose mistakes are one line naming the (sub)command, exit code 2.

    argparse prints the whole usage block before its message; a user wants the
    message and where to read more. Subparsers are made of this class too
    (``add_subparsers`` uses the parent's), and each records itself in the
    namespace it parses, so that arguments left over are reported by the
    subcommand they were given to.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: {message} (`{self.prog} --help` for more)\n")

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, extras = super().parse_known_args(args, namespace)
        if getattr(parsed, "parser", None) is None:  # the innermost subcommand sets it first
            parsed.parser = self
        return parsed, extras


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``poise`` (also used to document the CLI)."""
    parser = _Parser(
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
    for group in (serve, runs, bridge, logs, listing, inspect):
        group.add_parsers(commands)
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
    args, extras = build_parser().parse_known_args(argv)
    if extras:
        args.parser.error(f"unrecognized arguments: {' '.join(extras)}")
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(name)s %(levelname)s %(message)s"
    )
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        return int(args.handler(args))
    except KeyboardInterrupt:
        print(f"poise {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `poise log info LOG | head`: the reader left; nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # for the exit's flush
        return 128 + signal.SIGPIPE
    except Exception as exc:
        mistake = as_usage_error(exc)
        if mistake is None or args.debug:
            raise
        print(f"poise {args.command}: {mistake}", file=sys.stderr)
        return 2
