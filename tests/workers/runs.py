"""Helpers of the worker tests and the queue benchmark: queued runs recorded as the upload endpoint
records them (the recordings themselves need not exist), a worker running in a thread, waiting for
a condition, and the environment in which `fleetcal` runs as a plain process."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

from service import repository
from service.db import Database
from service.models import Run, RunKind
from service.settings import Settings
from tests.service.uploads import new_upload
from tests.workers.jobs import SCRIPTED
from workers.policy import RetryPolicy
from workers.worker import Worker, WorkerOptions

ROOT = Path(__file__).resolve().parents[2]
FAST_RETRY = RetryPolicy(backoff_base=timedelta(milliseconds=50), jitter=0)


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
            upload = new_upload(
                robot_id, run_id=run_id, kind=kind, config=config, max_attempts=max_attempts
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


@contextlib.contextmanager
def running_worker(settings: Settings, **options: Any) -> Iterator[Worker]:
    defaults: dict[str, Any] = {
        "job": SCRIPTED,
        "poll_interval": timedelta(milliseconds=50),
        "retry": FAST_RETRY,
    }
    worker = Worker(settings, WorkerOptions(**(defaults | options)))
    thread = threading.Thread(target=worker.run, name="test-worker")
    thread.start()
    try:
        yield worker
    finally:
        worker.request_stop(now=True)
        thread.join(60)
        assert not thread.is_alive()


def wait_for(what: str, predicate: Callable[[], bool], timeout: float = 60) -> None:
    """Poll until `predicate` holds; the timeout only keeps a broken worker from hanging CI."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"still waiting for {what} after {timeout} s")
        time.sleep(0.05)


def run_row(db: Database, run_id: uuid.UUID) -> Run:
    with db.session() as session:
        run = session.get(Run, run_id)
        assert run is not None
        return run


def entrypoint_env(**settings: str) -> dict[str, str]:
    """This machine's environment for a role, with `fleetcal` from the virtualenv on the PATH
    (as in the image) and the repository importable (for the test job)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLEETCAL_")}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(ROOT)
    env.update(settings)
    return env
