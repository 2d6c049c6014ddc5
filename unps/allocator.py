"""Keep freed memory for reuse instead of handing it back to the kernel at every step.

glibc's malloc serves blocks above its mmap threshold with fresh ``mmap`` calls and unmaps them on
``free``, so a fit that allocates the same multi-megabyte tensors every step pays for zeroed pages
each time: up to a quarter of a DiLiGenT fit's CPU time went to the kernel. Raising the mmap threshold to
its ceiling and the trim threshold to 1 GiB keeps such blocks in the heap; the arithmetic, and so
every result, is unchanged.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024   # glibc's ceiling on 64-bit systems
TRIM_THRESHOLD = 1 << 30


def keep_freed_memory() -> bool:
    """Ask glibc's malloc to reuse freed blocks of up to 32 MiB; True where it accepted.

    Anywhere else (macOS, Windows, musl) it does nothing and returns False.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX)) and bool(mallopt(M_TRIM_THRESHOLD,
                                                                                   TRIM_THRESHOLD))
