"""Per-cloud work over threads: as many as `OMP_NUM_THREADS` says (else the CPUs), results in
the order of the work whichever thread finishes first."""

from __future__ import annotations

import os
import threading
import time

import pytest

from pipeline.parallel import cloud_threads, map_clouds


@pytest.mark.parametrize(("pinned", "threads"), [("1", 1), ("3", 3), (" 2 ", 2)])
def test_omp_num_threads_sets_the_thread_count(
    pinned: str, threads: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", pinned)
    assert cloud_threads() == threads


@pytest.mark.parametrize("pinned", ["", "0", "two", "2,1"])
def test_without_a_usable_pin_every_cpu_of_the_process_counts(
    pinned: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", pinned)
    assert cloud_threads() == len(os.sched_getaffinity(0))


def test_results_come_in_the_order_of_the_work_from_several_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "4")
    names: set[str] = set()

    def slow_square(n: int) -> int:
        names.add(threading.current_thread().name)
        time.sleep(0.002 * (8 - n))  # the first items finish last
        return n * n

    assert map_clouds(slow_square, range(8)) == [n * n for n in range(8)]
    assert len(names) > 1
    assert all(name.startswith("fleetcal-cloud") for name in names)


def test_one_thread_runs_the_work_in_the_callers_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    names = map_clouds(lambda _: threading.current_thread().name, range(3))
    assert names == [threading.current_thread().name] * 3
    assert map_clouds(lambda n: n, []) == []
