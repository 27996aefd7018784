"""Webhooks end to end, on SQLite and PostgreSQL: `fleetcal worker` processes deliver the outbox
to a receiver started here that answers 500 twice, hangs on a delivery while its worker is killed
with SIGKILL, and is restarted on its port. After dropping repeats by event id the receiver holds
every event exactly once, and every signature verifies."""

from __future__ import annotations

import threading
import uuid
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import select

from service import webhooks as registry
from service.db import Database
from service.models import DeliveryStatus, EventType, WebhookDelivery
from service.settings import Settings
from tests.reliability.harness import processes, start_worker, wait_for
from tests.service.documents import result_document
from tests.service.webhook_receiver import Receiver
from tests.workers.jobs import SCRIPTED
from tests.workers.runs import enqueue, finished_run
from workers import queue

pytestmark = pytest.mark.slow

SECRET = "whsec_reliability_0123456789abcdef"
WAIT_S = 120  # only keeps a broken worker from hanging CI; never a timing assertion
FAST_WEBHOOKS = {
    "FLEETCAL_WEBHOOK_BACKOFF_SECONDS": "0.2",
    "FLEETCAL_WEBHOOK_TIMEOUT_SECONDS": "2",
    "FLEETCAL_WEBHOOK_LEASE_SECONDS": "4",
}


@pytest.fixture
def db(settings: Settings) -> Iterator[Database]:
    database = Database.from_settings(settings)
    yield database
    database.dispose()


def _events(db: Database) -> set[tuple[str, str]]:
    """Four runs raising seven events, as the worker's transactions raise them."""
    drifted = result_document(passed=False)
    drifted["verdict"]["checks"].append(
        {"name": "drift_rotation:lidar_rear", "value": 0.9, "limit": 0.5, "passed": False}
    )
    passed = finished_run(db, result_document(passed=True))
    failed = finished_run(db, result_document(passed=False, final=0.02))
    drift = finished_run(db, drifted, robot_id="R2")
    lost = enqueue(db, "R3")
    held = queue.claim(db, "test-worker", timedelta(minutes=1))
    assert held is not None and held.run_id == lost
    problem = {"type": "urn:fleetcal:problem:x", "title": "X", "status": 422, "detail": "no"}
    queue.fail(db, held, problem)
    expected = {
        ("run.finished", passed),
        ("run.finished", failed),
        ("verdict.failed", failed),
        ("run.finished", drift),
        ("verdict.failed", drift),
        ("drift.exceeded", drift),
        ("run.failed", lost),
    }
    return {(kind, str(run_id)) for kind, run_id in expected}


def _refused_once(db: Database) -> bool:
    """Whether a delivery was refused at the connection (the receiver was down)."""
    with db.session() as session:
        errors = session.scalars(select(WebhookDelivery.last_error))
        return any("ConnectError" in (error or "") for error in errors)


def _all_delivered(db: Database, expected: int) -> bool:
    """Whether there are `expected` deliveries, all delivered."""
    with db.session() as session:
        statuses = list(session.scalars(select(WebhookDelivery.status)))
    return len(statuses) == expected and all(s == DeliveryStatus.DELIVERED for s in statuses)


def test_every_event_arrives_once_across_a_killed_worker_and_a_restarted_receiver(
    settings: Settings, db: Database, tmp_path: Path
) -> None:
    hanging, release = threading.Event(), threading.Event()

    def script(number: int, event: dict[str, Any]) -> int:
        if number <= 2:
            return 500
        if number == 3:
            hanging.set()
            release.wait(WAIT_S)  # answers only after its worker is dead: it must come again
        return 200

    receiver = Receiver(SECRET, script=script).start()
    with db.transaction() as session:
        registry.create_webhook(
            session, url=receiver.url, events=list(EventType), robot_model=None, secret=SECRET
        )
    expected = _events(db)
    try:
        with processes() as workers:
            workers.append(
                start_worker(
                    settings, SCRIPTED, tmp_path / "w1.log", concurrency=1, **FAST_WEBHOOKS
                )
            )
            wait_for("the third delivery to be in flight", hanging.is_set, WAIT_S)
            workers[0].kill()
            release.set()
            receiver.stop()  # the receiver goes down for a redeploy while a new worker starts
            workers.append(
                start_worker(
                    settings, SCRIPTED, tmp_path / "w2.log", concurrency=1, **FAST_WEBHOOKS
                )
            )

            wait_for(
                "a delivery refused by the stopped receiver", lambda: _refused_once(db), WAIT_S
            )
            receiver.start()
            wait_for("every delivery", lambda: _all_delivered(db, len(expected)), WAIT_S)
            output = workers[1].output()
    finally:
        release.set()
        receiver.stop()
    assert all(request["signature_valid"] for request in receiver.requests)
    got = {(event["type"], event["run"]["id"]) for event in receiver.events.values()}
    assert got == expected, output
    assert len(receiver.events) == len(expected)
    assert [request["status"] for request in receiver.requests[:2]] == [500, 500]
    # The delivery in flight when its worker died was answered, then sent again by the next worker.
    assert receiver.duplicates >= 1
    hung = uuid.UUID(receiver.requests[2]["event_id"])
    with db.session() as session:
        row = session.scalars(select(WebhookDelivery).where(WebhookDelivery.event_id == hung)).one()
    assert row.attempts >= 2 and row.status == DeliveryStatus.DELIVERED
