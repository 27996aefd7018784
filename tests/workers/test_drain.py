"""Several `fleetcal worker` processes drain one queue: every run is done, none of them twice
(the benchmark's drain at a small scale, on SQLite and on PostgreSQL)."""

from __future__ import annotations

import pytest

from service.settings import Settings
from tests.bench.bench_queue import LIDARS_PER_RESULT, drain


@pytest.mark.slow
def test_worker_processes_drain_the_queue_none_lost_none_twice(settings: Settings) -> None:
    result = drain(settings, runs=30, workers=2, timeout=300)
    assert result.succeeded == 30 and result.lost == 0
    assert result.first_attempt == 30, "no run was claimed twice"
    assert result.results == 30 and result.extrinsics_rows == LIDARS_PER_RESULT * 30
    assert result.duplicated == 0
