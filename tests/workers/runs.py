"""Queued runs for the worker tests and the queue benchmark, recorded as the upload endpoint
records them (the recordings themselves need not exist)."""

from __future__ import annotations

import uuid
from datetime import timedelta
from typing import Any

from service import repository
from service.db import Database
from service.models import RunKind


def enqueue_many(
    db: Database,
    count: int,
    *,
    robots: int = 1,
    prefix: str = "R",
    kind: RunKind = RunKind.END_OF_LINE,
    max_attempts: int = 3,
    config: dict[str, object] | None = None,
) -> list[uuid.UUID]:
    """`count` queued runs spread over robots `<prefix>0..`, in one transaction."""
    ids = [uuid.uuid4() for _ in range(count)]
    with db.transaction() as session:
        for index, run_id in enumerate(ids):
            robot_id = f"{prefix}{index % robots}" if robots > 1 else prefix
            upload = repository.NewUpload(
                run_id=run_id,
                robot_id=robot_id,
                kind=kind,
                size=1,
                sha256="0" * 64,
                format="mcap",
                storage_key=f"recordings/{robot_id}/{run_id}",
                idempotency_key=None,
                config=config,
                max_attempts=max_attempts,
            )
            repository.record_upload(session, upload, create_robot=True)
    return ids


def enqueue(
    db: Database,
    robot_id: str = "R1",
    *,
    kind: RunKind = RunKind.END_OF_LINE,
    max_attempts: int = 3,
    config: dict[str, object] | None = None,
) -> uuid.UUID:
    """One queued run of `robot_id`."""
    return enqueue_many(
        db, 1, prefix=robot_id, kind=kind, max_attempts=max_attempts, config=config
    )[0]


def finished_run(
    db: Database,
    document: dict[str, Any],
    robot_id: str = "R1",
    *,
    kind: RunKind = RunKind.END_OF_LINE,
) -> uuid.UUID:
    """A run of `robot_id` that a worker has claimed and completed with `document`."""
    from workers import queue

    run_id = enqueue(db, robot_id, kind=kind)
    held = queue.claim(db, "test-worker", timedelta(minutes=1))
    assert held is not None and held.run_id == run_id, "the queue held another run"
    queue.complete(db, held, document)
    return run_id
