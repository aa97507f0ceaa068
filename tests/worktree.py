"""The working tree as ``git status`` sees it, to check that the tests leave it as they found it."""

from __future__ import annotations

import subprocess
from pathlib import Path, PurePosixPath

CACHE_NAMES = frozenset(
    {"__pycache__", ".pytest_cache", ".hypothesis", ".ruff_cache", ".mypy_cache"}
)
"""Directories that tools, not tests, write (byte code, pytest's and Hypothesis' caches)."""


def tree_status(root: Path) -> frozenset[str] | None:
    """``git status --porcelain`` lines of ``root``, ignored files included, caches left out.

    Returns ``None`` where ``root`` is not a git working tree (an unpacked
    source archive) or git is missing: then there is nothing to compare.
    """
    try:
        result = subprocess.run(
            ["git", "status", "--porcelain", "--ignored=matching", "--untracked-files=all"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    if result.returncode != 0:
        return None
    return frozenset(
        line
        for line in result.stdout.splitlines()
        if not CACHE_NAMES & set(PurePosixPath(line[3:].strip('"').rstrip("/")).parts)
    )


def changes(before: frozenset[str], after: frozenset[str]) -> list[str]:
    """Entries of ``after`` that ``before`` lacks: files the run wrote, changed or removed."""
    return sorted(after - before)
