"""A one-line progress bar on stderr, drawn only on a terminal (no carriage returns in logs)."""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["ProgressBar"]

WIDTH = 30


class ProgressBar:
    """``with ProgressBar(label) as bar: bar(fraction)``; the line is cleared on exit.

    The line shows the label, the bar, the fraction, an optional detail
    (``bar(0.4, "48/≤120 trials")``) and, once a few seconds have passed, the
    time left at the pace so far.

    Args:
        label: What progresses (a scenario name, a log file, a sweep).
        enabled: Draw at all (``False``: a quiet run).
        stream: Where to draw; nothing is drawn unless it is a terminal.
    """

    def __init__(self, label: str, *, enabled: bool = True, stream: TextIO | None = None):
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled and self.stream.isatty()
        self._start_s = time.monotonic()
        self._line = ""

    def __call__(self, fraction: float, detail: str = "") -> None:
        """Draw the bar at ``fraction`` (0 to 1) of the work, with an optional ``detail``."""
        if not self.enabled:
            return
        fraction = min(max(fraction, 0.0), 1.0)
        filled = int(WIDTH * fraction)
        line = f"{self.label[:28]:<28} [{'#' * filled}{'.' * (WIDTH - filled)}] {fraction:4.0%}"
        if detail:
            line += f" {detail}"
        elapsed_s = time.monotonic() - self._start_s
        if 0.0 < fraction < 1.0 and elapsed_s > 5.0:
            left_s = round(elapsed_s * (1.0 - fraction) / fraction)
            line += f" {left_s // 60}:{left_s % 60:02d} left"
        self._draw(line)

    def print(self, text: str) -> None:
        """Print ``text`` to stdout as a line of its own, the bar redrawn below it."""
        if self.enabled:
            self._clear()
        print(text, flush=True)
        if self.enabled and self._line:
            self._draw(self._line)

    def _draw(self, line: str) -> None:
        padding = " " * max(0, len(self._line) - len(line))
        self.stream.write(f"\r{line}{padding}")
        self.stream.flush()
        self._line = line

    def _clear(self) -> None:
        self.stream.write("\r" + " " * max(WIDTH + 40, len(self._line)) + "\r")
        self.stream.flush()

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self.enabled:
            self._clear()
