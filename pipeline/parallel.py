"""Work on independent stop clouds spread over this process's CPUs.

Moving points, the floor fits, stage 1 and segmentation treat each (LiDAR, stop) cloud alone, and
their heavy parts (numpy's array operations, pykdtree's queries) release the GIL, so threads
share that work without copying the clouds. How many: `OMP_NUM_THREADS` where it is set (the
service's pool children and the benchmarks pin it to 1, running one process per core instead),
else every CPU this process may use. Each cloud's result is the same whichever thread computes it
(no shared random state: every fit seeds its own generator), so a calibration's result does not
depend on the thread count.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")


def cloud_threads() -> int:
    """Threads for per-cloud work: `OMP_NUM_THREADS` where it is a positive integer, else the
    CPUs this process may run on."""
    pinned = os.environ.get("OMP_NUM_THREADS", "").strip()
    if pinned.isdigit() and int(pinned) > 0:
        return int(pinned)
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def map_clouds(function: Callable[[T], R], items: Iterable[T]) -> list[R]:
    """`[function(item) for item in items]`, on `cloud_threads()` threads; in order."""
    work = list(items)
    threads = min(cloud_threads(), len(work))
    if threads <= 1:
        return [function(item) for item in work]
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="fleetcal-cloud") as pool:
        return list(pool.map(function, work))
