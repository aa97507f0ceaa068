"""A one-line progress bar on stderr, drawn only on a terminal (no carriage returns in logs)."""

from __future__ import annotations

import sys
from typing import TextIO

__all__ = ["ProgressBar"]

WIDTH = 30


class ProgressBar:
    """``with ProgressBar(label) as bar: bar(fraction)``; the line is cleared on exit.

    Args:
        label: What progresses (a scenario name, a log file).
        enabled: Draw at all (``False``: a quiet run).
        stream: Where to draw; nothing is drawn unless it is a terminal.
    """

    def __init__(self, label: str, *, enabled: bool = True, stream: TextIO | None = None):
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled and self.stream.isatty()

    def __call__(self, fraction: float) -> None:
        """Draw the bar at ``fraction`` (0 to 1) of the work."""
        if not self.enabled:
            return
        filled = int(WIDTH * min(max(fraction, 0.0), 1.0))
        self.stream.write(
            f"\r{self.label[:28]:<28} [{'#' * filled}{'.' * (WIDTH - filled)}] {fraction:4.0%}"
        )
        self.stream.flush()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self.enabled:
            self.stream.write("\r" + " " * (WIDTH + 40) + "\r")
            self.stream.flush()
