"""The C allocator of a process that solves: large arrays kept in the heap between solves.

A Newton step allocates and frees tangent-sized arrays (megabytes) hundreds of times. glibc
serves such blocks by ``mmap`` and, by default, raises its threshold as it sees them freed,
so that after the first few they come from the heap. Setting ``MALLOC_TRIM_THRESHOLD_`` (or
``MALLOC_MMAP_THRESHOLD_``) in the environment switches that adaptation off: every large array
is then mapped, zero-filled by the kernel page by page and unmapped again. Dask's nanny sets
``MALLOC_TRIM_THRESHOLD_=65536`` in every worker it starts, which made a protocol's solve in a
Dask worker 1.5x slower than in a plain worker process (``skinkit bench forward``). A worker
therefore restores the adaptive behaviour's upper values at its first solve.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: glibc's ``mallopt`` parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: the values glibc's adaptation reaches on 64-bit systems for arrays of this size: blocks up
#: to 32 MiB from the heap, up to 64 MiB of freed heap kept for the next step
MMAP_THRESHOLD_BYTES = 32 * 2**20
TRIM_THRESHOLD_BYTES = 64 * 2**20
_ENV = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")
_done = False


def keep_large_blocks() -> bool:
    """Raise glibc's mmap and trim thresholds when the environment has fixed them low (once per
    process); True when they were changed. Elsewhere (another C library, thresholds left to
    glibc's adaptation) nothing is changed."""
    global _done
    if _done:
        return False
    _done = True
    if not any(k in os.environ for k in _ENV):
        return False
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
    return bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1 and ok)


__all__ = ["MMAP_THRESHOLD_BYTES", "TRIM_THRESHOLD_BYTES", "keep_large_blocks"]
