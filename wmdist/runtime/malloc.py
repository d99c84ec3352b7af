"""Keep freed tensor memory in the process instead of returning it to the kernel.

glibc serves blocks above its mmap threshold (128 KiB, rising to at most 32 MiB as large
blocks are freed) with a fresh mmap, and trims the heap top when it frees. A learner
allocates and frees the same tens of megabytes every update, so each update then pays a
page fault per 4 KiB page it touches again. Measured on the small DreamerV3 update (bf16,
2 threads): 0.51 s -> 0.46 s per update. Pinning the threshold at its maximum and trimming
only above 1 GiB keeps those pages mapped; peak memory is unchanged.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import sys

_M_TRIM_THRESHOLD = -1  # glibc's mallopt parameter numbers (malloc.h)
_M_MMAP_THRESHOLD = -3
_MMAP_MAX = 32 * 1024 * 1024  # glibc's ceiling for M_MMAP_THRESHOLD on 64-bit (HEAP_MAX_SIZE / 2)
_TRIM = 1 << 30

_done = False


def tune_malloc() -> bool:
    """Apply once per process; True if glibc took the settings (a no-op elsewhere)."""
    global _done
    if _done:
        return True
    if not sys.platform.startswith("linux"):
        return False
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and other libcs have no mallopt
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    _done = bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_MAX)) and bool(mallopt(_M_TRIM_THRESHOLD, _TRIM))
    return _done
