"""Process-wide settings of the native libraries a calibration leans on.

A calibration allocates and frees arrays of tens of megabytes thousands of times (neighbourhoods
of 80 points over a stop cloud, the optimisation's point groups). glibc's defaults hand each such
block back to the kernel when it is freed and fault it in again, page by page, at the next
allocation: on the full-rate set 1 recording 520k page faults and 1.1-1.4 s of system time of
12-14 s of CPU, against 66k faults and 0.2-0.3 s with the thresholds below, the peak memory the
same (`tune_allocator`). OpenMP's worker threads (pykdtree's queries) spin between parallel
regions by default, burning the other core while numpy works on one: 1.6-1.9 s of CPU more than
with passive waiting and no faster (`PASSIVE_OPENMP`, set by `pipeline/__init__.py` before any
kd-tree loads).
"""

from __future__ import annotations

import ctypes
import functools
import sys

PASSIVE_OPENMP = ("OMP_WAIT_POLICY", "PASSIVE")
"""The environment variable (and value) that makes idle OpenMP threads sleep instead of spin.
Read once, when the OpenMP runtime loads: a value already in the environment wins."""

MMAP_THRESHOLD_BYTES = 32 << 20
"""Blocks below this come from the heap, reused after a free (glibc's largest allowed value)."""
TRIM_THRESHOLD_BYTES = 64 << 20
"""Free memory at the top of the heap kept for the next allocation up to this much (128 KiB by
default; 64 MiB measured as good as 256 MiB)."""

_M_TRIM_THRESHOLD = -1  # mallopt's parameter numbers, from glibc's malloc.h
_M_MMAP_THRESHOLD = -3


@functools.cache
def tune_allocator() -> bool:
    """Set glibc's mmap and trim thresholds for this process (once; later calls do nothing).
    True where they were set; False on another C library (musl, macOS), which is left alone."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    # mallopt returns 1 on success; 0 where glibc refuses the value.
    return bool(
        mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
        and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
    )
