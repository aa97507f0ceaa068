"""Give freed message buffers back to the operating system (glibc's malloc).

glibc serves a large allocation with ``mmap`` and returns it to the system when
freed, but after the first such free it raises that threshold (up to 32 MiB)
and later buffers of a few MB come from the heap, whose freed pages a
fragmented heap keeps: the broker kept 28 MB after its first 14 MB message
(issue 32; 76 MB with the threshold fixed, 104 MB without, over thirteen such
messages). Fixing the threshold turns the adjustment off, so a message's
buffers leave with it.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

__all__ = ["MMAP_THRESHOLD_BYTES", "return_large_buffers_to_the_system"]

log = logging.getLogger(__name__)

MMAP_THRESHOLD_BYTES = 256 * 1024
"""Allocations this large or larger are mapped on their own and unmapped when freed."""
_M_MMAP_THRESHOLD = -3  # glibc's malloc.h


def return_large_buffers_to_the_system() -> bool:
    """Fix glibc's mmap threshold at :data:`MMAP_THRESHOLD_BYTES`; ``False`` if not glibc."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError, TypeError):  # not glibc (musl, macOS): nothing to do
        log.debug("no mallopt in %s: large buffers follow the allocator's own policy", name)
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
