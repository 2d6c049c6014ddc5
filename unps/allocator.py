"""Keep freed memory for reuse instead of handing it back to the kernel at every step.

glibc's malloc serves blocks above its mmap threshold (at most 32 MiB) with fresh ``mmap`` calls
and unmaps them on ``free``, so a fit that allocates the same large tensors every step pays for
zeroed pages each time: up to a quarter of a fast-preset fit's CPU time, and 40 % of a paper-preset
step's wall time at full resolution, whose tensors (96 images, 384 channels) are larger than any
threshold. With ``mmap`` turned off every block comes from the heap, and a trim threshold of 1 GiB
keeps what is freed there: a paper-preset step on cat went from 13.8 s to 8.3 s on a 2-core CPU, its
peak resident memory from 6.4 to 8.1 GB (experiments/speed/README.md). The arithmetic, and so every
result, is unchanged.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
TRIM_THRESHOLD = 1 << 30


def keep_freed_memory() -> bool:
    """Ask glibc's malloc to serve every block from its heap and keep what is freed there; True
    where it accepted.

    A block the heap cannot grow by still gets its own mapping (glibc falls back to ``mmap``
    there, and in the arenas of threads other than the main one). Anywhere else (macOS, Windows,
    musl) it does nothing and returns False.
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    accepted = [mallopt(M_MMAP_MAX, 0), mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)]
    return all(accepted)
