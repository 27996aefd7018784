"""The job queue on the database: the `runs` table is the queue (DESIGN.md).

Semantics follow Solid Queue, River and Oban. `claim` takes the oldest available `queued` run
(`FOR UPDATE SKIP LOCKED` on PostgreSQL; on SQLite the `BEGIN IMMEDIATE` write lock serialises
claimers), counts an attempt and grants a lease; `renew` is the heartbeat; `complete` writes the
result and the final status in one transaction; `retry` and `fail` end an attempt; `give_back`
returns a run untouched (shutdown); `reap` re-queues runs whose lease expired, or fails them once
their attempts are used up. Every write after the claim is conditional on the lease owner, so a
worker that lost its lease can never overwrite the run's new holder, and the result is unique per
run (its primary key is the run id), so nothing is ever stored twice.

Times of the lease come from the database's clock on PostgreSQL, so workers on many machines agree
on when a lease expires; the embedded SQLite database lives on one machine and uses its clock.
"""

from __future__ import annotations

import uuid
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import CursorResult, func, or_, select, update
from sqlalchemy.orm import Session

from service import repository
from service.db import Database
from service.models import DeliveryStatus, Run, RunKind, RunStatus, WebhookDelivery
from workers.policy import Failure, FailureKind, exhausted_problem

REAP_BATCH = 100


@dataclass(frozen=True)
class Claim:
    """A run held by one worker for one attempt. `lease_owner` names the worker *and* the attempt,
    so even the same worker re-claiming the run later cannot act on the old attempt's behalf."""

    run_id: uuid.UUID
    robot_id: str
    kind: RunKind
    storage_key: str
    upload_format: str
    config: dict[str, Any] | None
    attempt: int
    max_attempts: int
    lease_owner: str
    created_at: datetime
    available_at: datetime
    claimed_at: datetime


@dataclass(frozen=True)
class Reaped:
    """What one pass of the reaper did: runs put back in the queue and runs it failed."""

    requeued: tuple[uuid.UUID, ...] = ()
    failed: tuple[uuid.UUID, ...] = ()


def db_now(session: Session) -> datetime:
    """The time every lease is measured in (see the module docstring)."""
    bind = session.get_bind()
    if bind.dialect.name == "postgresql":
        now = session.scalar(select(func.now()))
        assert isinstance(now, datetime)
        return now.astimezone(UTC)
    return datetime.now(UTC)


def claim(db: Database, worker_id: str, lease: timedelta) -> Claim | None:
    """Take the oldest run that is queued and available, or None if there is none."""
    with db.transaction() as session:
        now = db_now(session)
        run = session.scalars(
            select(Run)
            .where(Run.status == RunStatus.QUEUED, Run.available_at <= now)
            .order_by(Run.available_at, Run.created_at, Run.id)
            .limit(1)
            .with_for_update(skip_locked=True)
        ).first()
        if run is None:
            return None
        run.status = RunStatus.RUNNING
        run.attempts += 1
        run.lease_owner = f"{worker_id}#{run.attempts}"
        run.lease_expires_at = now + lease
        run.heartbeat_at = now
        run.started_at = now
        run.stage = "claimed"
        run.progress = 0.0
        run.updated_at = now
        return Claim(
            run_id=run.id,
            robot_id=run.robot_id,
            kind=run.kind,
            storage_key=run.storage_key,
            upload_format=run.upload_format,
            config=run.config,
            attempt=run.attempts,
            max_attempts=run.max_attempts,
            lease_owner=run.lease_owner,
            created_at=run.created_at,
            available_at=run.available_at,
            claimed_at=now,
        )


def renew(
    db: Database,
    held: Claim,
    lease: timedelta,
    *,
    stage: str | None = None,
    progress: float | None = None,
) -> bool:
    """The heartbeat: extend the lease (and record the stage, if given). False if the lease is
    lost: the run was reaped and re-queued, given to another worker, or finished meanwhile."""
    with db.transaction() as session:
        now = db_now(session)
        values: dict[str, Any] = {"lease_expires_at": now + lease, "heartbeat_at": now}
        if stage is not None:
            values.update(stage=stage, progress=progress, updated_at=now)
        return _held_update(session, held, values) == 1


def complete(db: Database, held: Claim, document: dict[str, Any]) -> None:
    """Store the result, its extrinsics rows and status `succeeded`, in one transaction.

    Raises `repository.LeaseLostError` if the run is no longer ours, `RunFinishedError` if it
    already has its final status (a result is never written twice)."""
    with db.transaction() as session:
        repository.store_result(session, held.run_id, document, lease_owner=held.lease_owner)
        run = session.get(Run, held.run_id)
        assert run is not None
        run.stage = None


def fail(db: Database, held: Claim, problem: dict[str, Any]) -> None:
    """End the run `failed` with `problem` (an RFC 9457 document)."""
    with db.transaction() as session:
        repository.fail_run(session, held.run_id, problem, lease_owner=held.lease_owner)
        run = session.get(Run, held.run_id)
        assert run is not None
        run.stage = None


def retry(db: Database, held: Claim, delay: timedelta) -> bool:
    """Put the run back in the queue, available again after `delay` (the attempt counts)."""
    with db.transaction() as session:
        now = db_now(session)
        return _held_update(session, held, _requeued(now, now + delay)) == 1


def give_back(db: Database, held: Claim) -> bool:
    """Return the run to the queue at once without counting the attempt: the worker is stopping,
    the run did nothing wrong."""
    with db.transaction() as session:
        now = db_now(session)
        values = _requeued(now, now) | {"attempts": Run.attempts - 1}
        return _held_update(session, held, values) == 1


def reap(db: Database, spare: Collection[uuid.UUID] = ()) -> Reaped:
    """Re-queue runs whose lease expired, or fail those that used up their attempts, naming the
    stage the last holder had reached.

    `spare`: the runs the reaping worker holds. It never reaps those: it watches their pipeline
    processes itself, so an expired lease there only means its heartbeat ran late (a stalled
    machine or database), never that the run was abandoned. A run it gave up (a result it could
    not store) is no longer held, and is reaped like any other.

    Safe to run from every worker at once: the expired rows are locked (skipping those another
    reaper holds) and re-checked under the lock.
    """
    requeued: list[uuid.UUID] = []
    failed: list[uuid.UUID] = []
    with db.transaction() as session:
        now = db_now(session)
        abandoned = [
            Run.status == RunStatus.RUNNING,
            or_(Run.lease_expires_at < now, Run.lease_expires_at.is_(None)),
        ]
        if spare:
            abandoned.append(Run.id.not_in(list(spare)))
        expired = session.scalars(
            select(Run)
            .where(*abandoned)
            .order_by(Run.lease_expires_at)
            .limit(REAP_BATCH)
            .with_for_update(skip_locked=True)
        ).all()
        for run in expired:
            if run.attempts >= run.max_attempts:
                failure = Failure(
                    FailureKind.LOST,
                    "the worker holding the run stopped renewing its lease (killed, out of "
                    "memory, or cut off from the database)",
                    stage=run.stage,
                )
                repository.fail_run(session, run.id, exhausted_problem(failure, run.attempts))
                run.stage = None
                failed.append(run.id)
            else:
                # No backoff: a lost worker says nothing against the run; the lease was the wait.
                for name, value in _requeued(now, now).items():
                    setattr(run, name, value)
                requeued.append(run.id)
    return Reaped(tuple(requeued), tuple(failed))


def queue_depth(db: Database) -> int:
    with db.session() as session:
        return int(
            session.scalar(
                select(func.count()).select_from(Run).where(Run.status == RunStatus.QUEUED)
            )
            or 0
        )


def _requeued(now: datetime, available_at: datetime) -> dict[str, Any]:
    return {
        "status": RunStatus.QUEUED,
        "available_at": available_at,
        "lease_owner": None,
        "lease_expires_at": None,
        "heartbeat_at": None,
        "stage": None,
        "progress": None,
        "updated_at": now,
    }


def _held_update(session: Session, held: Claim, values: dict[str, Any]) -> int:
    return update_if_leased(session, Run, held.run_id, RunStatus.RUNNING, held.lease_owner, values)


def update_if_leased(
    session: Session,
    model: type[Run] | type[WebhookDelivery],
    row_id: uuid.UUID,
    status: RunStatus | DeliveryStatus,
    lease_owner: str,
    values: Mapping[str, Any],
) -> int:
    """Set `values` on row `row_id` of a leased table (runs, webhook deliveries) only while it
    is still in `status` under `lease_owner`'s lease; how many rows changed (0 or 1).

    A holder whose lease expired and was taken over changes nothing: the new holder's work
    stands."""
    result = session.execute(
        update(model)
        .where(model.id == row_id, model.status == status, model.lease_owner == lease_owner)
        .values(**values)
        .execution_options(synchronize_session=False)
    )
    assert isinstance(result, CursorResult)
    return result.rowcount
