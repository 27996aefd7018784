"""The worker with its process pool, on SQLite and PostgreSQL, running `tests.workers.jobs.scripted`
so that each outcome (success, bad input, crashes, slow runs, stop requests) is cheap to cause."""

from __future__ import annotations

import logging
import socket
import uuid
from collections.abc import Callable
from datetime import timedelta
from pathlib import Path

import pytest
from sqlalchemy import func, select

from service.db import Database
from service.models import Result, RunStatus
from service.settings import Settings
from tests.workers.runs import enqueue, run_row, running_worker, wait_for
from workers import queue
from workers.pool import BLAS_THREAD_VARIABLES, PoolError
from workers.worker import Worker, WorkerOptions


def finished(db: Database, *run_ids: uuid.UUID) -> Callable[[], bool]:
    final = (RunStatus.SUCCEEDED, RunStatus.FAILED)
    return lambda: all(run_row(db, run_id).status in final for run_id in run_ids)


def result_count(db: Database, run_id: uuid.UUID) -> int:
    with db.session() as session:
        query = select(func.count()).select_from(Result).where(Result.run_id == run_id)
        return int(session.scalar(query) or 0)


def test_runs_succeed_with_their_result_and_pinned_blas_threads(
    settings: Settings, db: Database
) -> None:
    runs = [enqueue(db, config={"report_environment": True}) for _ in range(3)]
    with running_worker(settings, concurrency=2):
        wait_for("three runs", finished(db, *runs))
    for run_id in runs:
        row = run_row(db, run_id)
        assert row.status == RunStatus.SUCCEEDED and row.attempts == 1
        assert row.stage is None and row.progress == 1.0 and row.lease_owner is None
        with db.session() as session:
            result = session.get(Result, run_id)
        assert result is not None and result.passed
        assert result.document["worker"]["environment"] == dict.fromkeys(BLAS_THREAD_VARIABLES, "1")


def test_the_results_warnings_go_to_the_workers_log(
    settings: Settings, db: Database, caplog: pytest.LogCaptureFixture
) -> None:
    warning = "the config's denoise.scan_patterns names 'lidar_top', which the recording lacks"
    run_id = enqueue(db, config={"warnings": [warning]})
    with caplog.at_level(logging.WARNING, logger="workers.worker"), running_worker(settings):
        # The worker logs them after it has stored the result: wait for the line itself.
        wait_for("the warning", lambda: f"run {run_id}: {warning}" in caplog.messages)
    assert run_row(db, run_id).status == RunStatus.SUCCEEDED


def test_bad_input_fails_the_run_at_once_with_the_typed_message(
    settings: Settings, db: Database
) -> None:
    run_id = enqueue(db, config={"fail": "bad_input"})
    with running_worker(settings):
        wait_for("the run", finished(db, run_id))
    row = run_row(db, run_id)
    assert row.status == RunStatus.FAILED and row.attempts == 1
    assert row.error is not None
    assert row.error["type"] == "urn:fleetcal:problem:bad-input"
    assert row.error["detail"] == "the recording has no stops: the robot never stood still for 1 s"
    assert row.error["stage"] == "work"
    assert result_count(db, run_id) == 0


def test_bad_input_is_logged_as_one_info_line_without_a_traceback(
    settings: Settings, db: Database, caplog: pytest.LogCaptureFixture
) -> None:
    run_id = enqueue(db, config={"fail": "bad_input"})
    with caplog.at_level(logging.DEBUG, logger="workers"), running_worker(settings):
        wait_for("the run", finished(db, run_id))
    about_the_failure = [r for r in caplog.records if "no stops" in r.getMessage()]
    assert [(r.levelno, r.getMessage()) for r in about_the_failure] == [
        (
            logging.INFO,
            f"run {run_id}: failed on bad input: "
            "the recording has no stops: the robot never stood still for 1 s",
        )
    ]
    assert not any("Traceback" in r.getMessage() for r in caplog.records)
    assert all(r.levelno < logging.WARNING for r in caplog.records if str(run_id) in r.getMessage())


def test_transient_errors_are_retried_until_the_attempts_run_out(
    settings: Settings, db: Database
) -> None:
    run_id = enqueue(db, config={"fail": "storage"}, max_attempts=3)
    with running_worker(settings):
        wait_for("the run", finished(db, run_id))
    row = run_row(db, run_id)
    assert row.status == RunStatus.FAILED and row.attempts == 3
    assert row.error is not None
    assert row.error["type"] == "urn:fleetcal:problem:storage-or-database-unavailable"
    assert "connection reset by peer" in row.error["detail"]


def test_a_crashed_pipeline_process_costs_one_attempt(settings: Settings, db: Database) -> None:
    """The child dies on the first attempt only; only its run is affected, and it succeeds on its
    second attempt in a fresh process while the other slot goes on."""
    crashing = enqueue(db, config={"die_on_attempts": [1]})
    healthy = enqueue(db, config={"sleep": 0.5})
    with running_worker(settings, concurrency=2):
        wait_for("both runs", finished(db, crashing, healthy))
    assert run_row(db, healthy).attempts == 1
    row = run_row(db, crashing)
    assert row.status == RunStatus.SUCCEEDED and row.attempts == 2
    assert result_count(db, crashing) == 1


def test_a_run_that_keeps_crashing_its_process_fails_after_max_attempts(
    settings: Settings, db: Database
) -> None:
    run_id = enqueue(db, config={"die_on_attempts": [1, 2, 3]}, max_attempts=3)
    with running_worker(settings):
        wait_for("the run", finished(db, run_id))
    row = run_row(db, run_id)
    assert row.status == RunStatus.FAILED and row.attempts == 3
    assert row.error is not None
    assert row.error["type"] == "urn:fleetcal:problem:worker-crashed"
    assert "killed by SIGKILL" in row.error["detail"] and "'work'" in row.error["detail"]


def test_stop_lets_a_running_run_finish(settings: Settings, db: Database) -> None:
    run_id = enqueue(db, config={"sleep": 1.0})
    waiting = enqueue(db)
    with running_worker(settings, shutdown_grace=timedelta(seconds=60)) as worker:
        wait_for("the claim", lambda: run_row(db, run_id).status == RunStatus.RUNNING)
        worker.request_stop()
        wait_for("the run", finished(db, run_id))
    assert run_row(db, run_id).status == RunStatus.SUCCEEDED
    assert run_row(db, waiting).status == RunStatus.QUEUED, "a draining worker claims nothing"


def test_stop_after_the_grace_gives_the_run_back_without_counting_it(
    settings: Settings, db: Database
) -> None:
    run_id = enqueue(db, config={"sleep": 30})
    with running_worker(settings, shutdown_grace=timedelta(milliseconds=200)) as worker:
        wait_for("the claim", lambda: run_row(db, run_id).status == RunStatus.RUNNING)
        worker.request_stop()
        wait_for("the give-back", lambda: run_row(db, run_id).status == RunStatus.QUEUED)
    row = run_row(db, run_id)
    assert row.attempts == 0 and row.lease_owner is None


def test_an_attempt_over_the_time_limit_is_stopped_and_retried(
    settings: Settings, db: Database
) -> None:
    run_id = enqueue(db, config={"sleep": 30}, max_attempts=2)
    with running_worker(settings, run_timeout=timedelta(milliseconds=300)):
        wait_for("the run", finished(db, run_id))
    row = run_row(db, run_id)
    assert row.status == RunStatus.FAILED and row.attempts == 2
    assert row.error is not None and row.error["type"] == "urn:fleetcal:problem:run-timeout"


def test_a_job_that_cannot_load_stops_the_worker_and_returns_the_run(
    settings: Settings, db: Database
) -> None:
    run_id = enqueue(db)
    worker = Worker(
        settings,
        WorkerOptions(
            job="tests.workers.jobs:no_such_job", poll_interval=timedelta(milliseconds=50)
        ),
    )
    with pytest.raises(PoolError, match="no_such_job"):
        worker.run()
    row = run_row(db, run_id)
    assert row.status == RunStatus.QUEUED and row.attempts == 0


def test_a_worker_waits_out_an_unreachable_database(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Nothing listens on the port: claims fail, the worker backs off and keeps going."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        closed_port = probe.getsockname()[1]
    settings = Settings(
        database_url=f"postgresql+psycopg://nobody@127.0.0.1:{closed_port}/none",
        storage_url=(tmp_path / "storage").as_uri(),
    )
    with caplog.at_level(logging.WARNING, logger="workers.worker"), running_worker(settings):
        wait_for(
            "two failed claims, each followed by a pause",
            lambda: sum("next try in" in r.message for r in caplog.records) >= 2,
        )


def test_the_heartbeat_keeps_a_run_longer_than_its_lease(settings: Settings, db: Database) -> None:
    """The run takes 2.5 leases; another worker's reaper (the test's) runs meanwhile and must
    leave it alone (the worker's own reaper spares the runs it holds whatever their lease)."""
    short_lease = settings.model_copy(update={"run_lease_seconds": 2})
    run_id = enqueue(db, config={"sleep": 5})
    reaped: list[queue.Reaped] = []

    def finished_unreaped() -> bool:
        reaped.append(queue.reap(db))
        return finished(db, run_id)()

    with running_worker(short_lease):
        wait_for("the run", finished_unreaped)
    row = run_row(db, run_id)
    assert row.status == RunStatus.SUCCEEDED and row.attempts == 1, "never reaped"
    assert set(reaped) == {queue.Reaped()}
