"""A push sweep's files: ``sweep_<scenario>.json`` and its picture, written whole or not at all.

The sweep rewrites both after every finished bisection and once more however it ends
(:func:`write_sweep`); an interrupt (Ctrl-C, SIGTERM) waits until both are written
(:func:`interrupts_held`), so the two always show the same trials.
"""

from __future__ import annotations

import json
import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from clients.sim.sweep import Sweep

__all__ = ["interrupts_held", "sweep_paths", "write_sweep"]


def sweep_paths(sweep: Sweep, output_dir: Path) -> tuple[Path, Path]:
    """``output_dir/sweep_<scenario>.json`` and ``.png``."""
    stem = output_dir / f"sweep_{sweep.scenario}"
    return stem.with_suffix(".json"), stem.with_suffix(".png")


def write_sweep(sweep: Sweep, output_dir: Path) -> tuple[Path, Path]:
    """Write ``sweep_<scenario>.json`` and ``sweep_<scenario>.png`` into ``output_dir``.

    Each is written under a temporary name beside it, then renamed over the old one
    (:func:`os.replace`). Ctrl-C and SIGTERM wait until both are written (about a second:
    the picture), so the two always show the same trials; then they stop the sweep.

    Returns:
        The paths of the JSON and the picture.
    """
    from clients.sim.sweep_plot import plot_sweep

    json_path, png_path = sweep_paths(sweep, output_dir)
    partial = json_path.with_suffix(".json.partial")
    with interrupts_held():
        try:
            partial.write_text(json.dumps(sweep.to_json(), indent=2))
            os.replace(partial, json_path)
            partial = png_path.with_suffix(".png.partial")
            plot_sweep(sweep, partial)
            os.replace(partial, png_path)
        finally:
            partial.unlink(missing_ok=True)  # gone once renamed
    return json_path, png_path


@contextmanager
def interrupts_held() -> Iterator[None]:
    """Ctrl-C and SIGTERM wait for the block: their handlers run once it ends.

    A KeyboardInterrupt raised inside matplotlib can be lost (the sweep ran on) or turned
    into another error (seen: a ``TypeError`` from one of its compiled functions), and a
    file left half-written. Blocking the signals would not do: the kernel hands them to
    another thread (a process pool's), and Python still runs the handler in the main one.
    So the handlers are swapped for one that notes the signal. Python runs signal handlers
    in the main thread only: elsewhere this holds nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []

    def hold(signum: int, _frame: object) -> None:
        held.append(signum)

    previous: dict[int, Any] = {
        signum: signal.signal(signum, hold) for signum in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        if held:  # as it would have been handled in the block
            handler = previous[held[0]]
            if callable(handler):
                handler(held[0], None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(held[0])
