"""What a recorded log holds, for a person: ``poise log info LOG`` and ``poise log plot LOG``.

``info``: sessions (one per recorded ``hello``) with their model, hash,
controller and parameters in force at the handshake, the duration, message
counts per type and direction, and the rate of states. ``plot``: the plot the
simulator writes for a run (:mod:`clients.sim.plots`), of the log's first session.
"""

from __future__ import annotations

import dataclasses
import os
import textwrap
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from clients.replay import read_recorded
from protocol.messages import Command, Hello, State, Welcome
from protocol.recording import BadLog, read_log

__all__ = ["LogSummary", "SessionSummary", "format_summary", "plot_log", "summarize_log"]


@dataclasses.dataclass
class SessionSummary:
    """One recorded session: its handshake."""

    model_name: str
    model_hash: str
    controller: str
    params: dict[str, Any]


@dataclasses.dataclass
class LogSummary:
    """A log's contents at a glance."""

    messages: int = 0
    duration_s: float = 0.0
    counts: Counter[str] = dataclasses.field(default_factory=Counter)
    """``"<type> <direction>"`` → messages."""
    sessions: list[SessionSummary] = dataclasses.field(default_factory=list)

    @property
    def state_rate_hz(self) -> float:
        """States sent per second of log time (0 for a log shorter than one message)."""
        states = self.counts["state sent"]
        return states / self.duration_s if self.duration_s > 0 else 0.0


def summarize_log(
    path: str | os.PathLike[str], progress: Callable[[float], None] | None = None
) -> LogSummary:
    """Read a log once and summarize it.

    Args:
        path: The MCAP log.
        progress: Optional callable told the fraction of the file read (0 to 1).

    Raises:
        BadLog: The file is not a readable Poise log.
    """
    summary = LogSummary()
    first_ns = last_ns = None
    awaiting_welcome = False
    for logged in read_log(path).reporting(progress):
        summary.messages += 1
        summary.counts[f"{logged.message.type} {logged.direction}"] += 1
        first_ns = logged.time_ns if first_ns is None else first_ns
        last_ns = logged.time_ns
        if isinstance(logged.message, Hello):  # sent by a client, received by a server
            awaiting_welcome = True
        elif isinstance(logged.message, Welcome) and awaiting_welcome:
            awaiting_welcome = False
            welcome = logged.message
            summary.sessions.append(
                SessionSummary(
                    welcome.model_name, welcome.model_hash, welcome.controller, welcome.params
                )
            )
    if first_ns is not None and last_ns is not None:
        summary.duration_s = (last_ns - first_ns) * 1e-9
    return summary


LINE_CHARS = 96
"""``poise log info`` wraps a long parameter (a per-joint list) at this width."""


def _parameter_text(value: object) -> str:
    """A parameter as the hello sent it; numbers in lists without trailing zeros."""
    if isinstance(value, list) and all(isinstance(v, int | float) for v in value):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    return repr(value)


def format_summary(path: str | os.PathLike[str], summary: LogSummary) -> str:
    """The text ``poise log info`` prints."""
    lines = [
        f"{os.fspath(path)}: {summary.messages} messages over {summary.duration_s:.3f} s, "
        f"{summary.state_rate_hz:.0f} states/s, {len(summary.sessions)} session(s)"
    ]
    for index, session in enumerate(summary.sessions, start=1):
        lines.append(
            f"session {index}: model {session.model_name} ({session.model_hash[:12]}…), "
            f"controller {session.controller}"
        )
        lines.append(f"  parameters ({len(session.params)}):")
        width = max((len(key) for key in session.params), default=0) + 2
        for key, value in sorted(session.params.items()):
            lines += textwrap.wrap(
                _parameter_text(value),
                LINE_CHARS,
                initial_indent=f"    {key:<{width}}",
                subsequent_indent=" " * (4 + width),
                break_on_hyphens=False,
            ) or [f"    {key}"]
    for key, count in sorted(summary.counts.items()):
        lines.append(f"  {key:<20}{count:>8}")
    if not summary.counts["command sent"] + summary.counts["command received"]:
        lines.append("  no recorded command: `poise replay` has nothing to compare")
    return "\n".join(lines)


def plot_log(
    path: str | os.PathLike[str],
    output_dir: str | os.PathLike[str],
    progress: Callable[[float], None] | None = None,
) -> Path:
    """Plot the first session of a log to ``output_dir/<log name>.png``; return the file.

    Time is each state's ``time_s``; pushes are not in a log, so none is shaded.
    ``progress`` is told the fraction of the file read (0 to 1), as it is read.

    Raises:
        BadLog: Not a log, or no state in it was answered by a command.
        ReplayError: The log holds no handshake.
    """
    from clients.sim.plots import PlotSeries, dof_names, plot_series

    session = read_recorded(path, progress).session
    time_s, commands = [], []
    for _, request in session.requests:
        reply = session.replies.get(request.seq)
        if isinstance(request, State) and isinstance(reply, Command):
            time_s.append(request.time_s)
            commands.append(reply)
    if not commands:
        raise BadLog(path, "no recorded state was answered by a command: nothing to plot")
    welcome = session.welcome
    series = PlotSeries(
        title=f"{Path(path).name} — {welcome.controller} controller, model "
        f"{welcome.model_name} (recorded; pushes are not logged)",
        time_s=np.asarray(time_s),
        commands=commands,
        dof_names=dof_names(welcome.joints),
    )
    output = Path(output_dir)
    output.mkdir(parents=True, exist_ok=True)
    plot_path = output / f"{Path(path).stem}.png"
    plot_series(series, plot_path)
    return plot_path
