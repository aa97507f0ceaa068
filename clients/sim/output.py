"""A run's output directory: one run at a time, the report rewritten after every scenario.

Two runs writing the same directory would silently mix their plots and
leave the last one's report: a run holds an exclusive lock on
``DIR/.poise-run.lock`` (``flock``, released by the kernel if the process
dies) and a second run into ``DIR`` is refused. ``report.json`` is replaced
atomically after each scenario, so a run killed or stopped half-way leaves
the report of what ran (a stopped scenario's entry says so).
"""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path
from types import TracebackType
from typing import Any

from protocol.errors import PoiseError

__all__ = ["OutputBusy", "OutputDirectory", "OutputUnusable"]

LOCK_NAME = ".poise-run.lock"


class OutputUnusable(PoiseError, OSError):
    """The output directory cannot be made (a file is in its way, no permission)."""


class OutputBusy(OutputUnusable):
    """Another run writes to the output directory; the message names it and what to do."""


class OutputDirectory:
    """``with OutputDirectory(path) as output: output.write_report(reports)``.

    Raises:
        OutputBusy: Another run holds the directory.
        OutputUnusable: The directory cannot be created (a file in the way, no permission).
    """

    def __init__(self, path: str | os.PathLike[str]):
        self.path = Path(path)
        self._lock_file: Any = None

    def __enter__(self) -> OutputDirectory:
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError):
            raise OutputUnusable(
                f"--output {str(self.path)!r}: a file is in the way (the output is a "
                "directory): choose another --output"
            ) from None
        except PermissionError as exc:
            raise OutputUnusable(
                f"--output {str(self.path)!r}: cannot create it ({exc.strerror}): "
                "choose another --output"
            ) from None
        lock = open(self.path / LOCK_NAME, "a+")  # closed in __exit__
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.seek(0)
            holder = lock.read().strip() or "?"
            lock.close()
            raise OutputBusy(
                f"{str(self.path)!r} is being written by another run (pid {holder}): "
                "wait for it to finish or choose another --output"
            ) from None
        lock.seek(0)
        lock.truncate()
        lock.write(str(os.getpid()))
        lock.flush()
        self._lock_file = lock
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        if self._lock_file is not None:
            self._lock_file.close()  # releases the flock
            self._lock_file = None

    def write_report(self, reports: list[dict[str, Any]]) -> Path:
        """Replace ``report.json`` with ``reports`` in one step (never half-written)."""
        path = self.path / "report.json"
        partial = path.with_suffix(".json.partial")
        partial.write_text(json.dumps(reports, indent=2))
        os.replace(partial, path)
        return path
