"""The queue's transactions on SQLite and PostgreSQL: claim order and exclusivity, leases and
heartbeats, the reaper, and outcomes that are written once and only by the lease holder."""

from __future__ import annotations

import threading
import time
import uuid
from datetime import UTC, datetime, timedelta

import pytest
from sqlalchemy import func, select

from service import repository
from service.db import Database
from service.models import Result, Run, RunStatus
from service.settings import Settings
from tests.service.documents import result_document
from tests.workers.runs import enqueue
from workers import queue

LEASE = timedelta(seconds=30)


def run_row(db: Database, run_id: uuid.UUID) -> Run:
    with db.session() as session:
        run = session.get(Run, run_id)
        assert run is not None
        return run


def expire_lease(db: Database, run_id: uuid.UUID) -> None:
    with db.transaction() as session:
        run = session.get(Run, run_id)
        assert run is not None
        run.lease_expires_at = datetime.now(UTC) - timedelta(seconds=1)


def test_claim_takes_the_oldest_available_run_and_leases_it(db: Database) -> None:
    first, second = enqueue(db), enqueue(db)
    later = enqueue(db)
    with db.transaction() as session:
        run = session.get(Run, later)
        assert run is not None
        run.available_at = datetime.now(UTC) + timedelta(hours=1)

    held = queue.claim(db, "w1", LEASE)
    assert held is not None and held.run_id == first
    assert held.attempt == 1 and held.lease_owner == "w1#1"
    row = run_row(db, first)
    assert row.status == RunStatus.RUNNING and row.attempts == 1
    assert row.lease_owner == "w1#1" and row.stage == "claimed"
    assert row.lease_expires_at is not None and row.started_at is not None
    assert row.lease_expires_at - row.started_at == LEASE

    again = queue.claim(db, "w1", LEASE)
    assert again is not None and again.run_id == second
    assert queue.claim(db, "w1", LEASE) is None, "a run backed off for an hour is not available"


def test_concurrent_claimers_never_take_the_same_run(settings: Settings) -> None:
    """Four claimers, each with its own engine (as separate workers have), race for 40 runs."""
    setup = Database.from_settings(settings)
    runs = {enqueue(setup) for _ in range(40)}
    setup.dispose()
    claimed: list[list[uuid.UUID]] = [[] for _ in range(4)]
    start = threading.Barrier(4)

    def claimer(index: int) -> None:
        db = Database.from_settings(settings)
        start.wait()
        while (held := queue.claim(db, f"w{index}", LEASE)) is not None:
            claimed[index].append(held.run_id)
        db.dispose()

    threads = [threading.Thread(target=claimer, args=(i,)) for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    every = [run_id for ids in claimed for run_id in ids]
    assert sorted(every) == sorted(runs), "each run claimed exactly once"


def test_heartbeat_extends_the_lease_and_records_the_stage(db: Database) -> None:
    enqueue(db)
    held = queue.claim(db, "w1", timedelta(seconds=5))
    assert held is not None
    before = run_row(db, held.run_id).lease_expires_at
    time.sleep(0.01)
    assert queue.renew(db, held, timedelta(seconds=60), stage="denoise", progress=0.3)
    row = run_row(db, held.run_id)
    assert row.lease_expires_at is not None and before is not None
    assert row.lease_expires_at - before > timedelta(seconds=50)
    assert (row.stage, row.progress) == ("denoise", 0.3)


def test_reaper_requeues_an_expired_lease_and_the_old_holder_loses_it(db: Database) -> None:
    run_id = enqueue(db)
    old = queue.claim(db, "dead", LEASE)
    assert old is not None
    assert queue.reap(db) == queue.Reaped(), "a live lease is left alone"
    expire_lease(db, run_id)

    assert queue.reap(db).requeued == (run_id,)
    row = run_row(db, run_id)
    assert row.status == RunStatus.QUEUED and row.attempts == 1 and row.lease_owner is None

    new = queue.claim(db, "alive", LEASE)
    assert new is not None and new.run_id == run_id and new.attempt == 2
    assert not queue.renew(db, old, LEASE), "the dead worker's heartbeat is refused"
    with pytest.raises(repository.LeaseLostError):
        queue.complete(db, old, result_document())
    queue.complete(db, new, result_document())
    row = run_row(db, run_id)
    assert row.status == RunStatus.SUCCEEDED and row.stage is None and row.progress == 1.0


def test_a_worker_never_reaps_the_runs_it_holds(db: Database) -> None:
    """An expired lease of a run the reaping worker holds means its heartbeat ran late, not that
    the run was abandoned; any other worker's reaper takes it back."""
    run_id = enqueue(db)
    held = queue.claim(db, "late", LEASE)
    assert held is not None
    expire_lease(db, run_id)

    assert queue.reap(db, spare={run_id}) == queue.Reaped()
    assert queue.renew(db, held, LEASE), "the late heartbeat still holds the run"
    expire_lease(db, run_id)
    assert queue.reap(db, spare={uuid.uuid4()}).requeued == (run_id,)


def test_reaper_fails_a_run_after_its_last_attempt_naming_the_stage(db: Database) -> None:
    run_id = enqueue(db, max_attempts=2)
    for attempt in (1, 2):
        held = queue.claim(db, f"w{attempt}", LEASE)
        assert held is not None and held.attempt == attempt
        queue.renew(db, held, LEASE, stage="optimise", progress=0.7)
        expire_lease(db, run_id)
        reaped = queue.reap(db)
    assert reaped.failed == (run_id,)
    row = run_row(db, run_id)
    assert row.status == RunStatus.FAILED and row.attempts == 2
    assert row.error is not None
    assert row.error["type"] == "urn:fleetcal:problem:worker-lost"
    assert "gave up after 2 attempts" in row.error["detail"]
    assert "'optimise'" in row.error["detail"]
    assert queue.claim(db, "w3", LEASE) is None


def test_a_result_is_stored_once_even_when_completed_twice(db: Database) -> None:
    run_id = enqueue(db)
    held = queue.claim(db, "w1", LEASE)
    assert held is not None
    queue.complete(db, held, result_document())
    with pytest.raises(repository.RunFinishedError):
        queue.complete(db, held, result_document(final=0.002))
    with db.session() as session:
        count = session.scalar(
            select(func.count()).select_from(Result).where(Result.run_id == run_id)
        )
        stored = session.get(Result, run_id)
    assert count == 1 and stored is not None and stored.metric_error_final == 0.0012


def test_retry_backs_off_and_give_back_does_not_count_the_attempt(db: Database) -> None:
    run_id = enqueue(db)
    held = queue.claim(db, "w1", LEASE)
    assert held is not None
    assert queue.retry(db, held, timedelta(minutes=10))
    row = run_row(db, run_id)
    assert row.status == RunStatus.QUEUED and row.attempts == 1
    assert row.available_at > datetime.now(UTC) + timedelta(minutes=9)
    assert queue.claim(db, "w1", LEASE) is None

    other = enqueue(db)
    held = queue.claim(db, "w2", LEASE)
    assert held is not None and held.run_id == other
    assert queue.give_back(db, held)
    row = run_row(db, other)
    assert row.status == RunStatus.QUEUED and row.attempts == 0 and row.lease_owner is None
    again = queue.claim(db, "w3", LEASE)
    assert again is not None and again.run_id == other and again.attempt == 1


def test_fail_records_the_problem_and_ends_the_lease(db: Database) -> None:
    run_id = enqueue(db)
    held = queue.claim(db, "w1", LEASE)
    assert held is not None
    problem = {"type": "urn:fleetcal:problem:no-stops", "title": "t", "status": 422, "detail": "d"}
    queue.fail(db, held, problem)
    row = run_row(db, run_id)
    assert row.status == RunStatus.FAILED and row.error == problem
    assert row.lease_owner is None and row.finished_at is not None
    assert not queue.retry(db, held, timedelta(0)), "a finished run cannot be re-queued"
