"""Webhook delivery from the outbox, on both databases, against a real receiver on loopback:
signed bodies, the event id header, backoff after a failure, the lease, a deleted webhook, and
giving up after the last attempt."""

from __future__ import annotations

import json
import threading
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta

import httpx
import pytest
from sqlalchemy import select

from service import webhooks as registry
from service.db import Database
from service.models import DeliveryStatus, EventType, WebhookDelivery
from tests.service.documents import result_document
from tests.service.webhook_receiver import Receiver
from tests.workers.runs import finished_run
from workers import webhooks
from workers.webhooks import DeliveryOptions, deliver_due

SECRET = "whsec_test_secret_0123456789"
FAST = DeliveryOptions(
    backoff_base=timedelta(milliseconds=1),
    timeout=timedelta(seconds=5),
    lease=timedelta(seconds=10),
)


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    running = Receiver(SECRET).start()
    yield running
    running.stop()


def register(
    db: Database, url: str, *events: EventType, robot_model: str | None = None
) -> uuid.UUID:
    with db.transaction() as session:
        hook = registry.create_webhook(
            session, url=url, events=list(events), robot_model=robot_model, secret=SECRET
        )
        return hook.id


def deliveries(db: Database) -> list[WebhookDelivery]:
    with db.session() as session:
        return list(session.scalars(select(WebhookDelivery).order_by(WebhookDelivery.created_at)))


def drain(db: Database, options: DeliveryOptions = FAST, rounds: int = 20) -> None:
    with httpx.Client(timeout=options.timeout.total_seconds()) as client:
        for _ in range(rounds):
            deliver_due(db, client, "test", options)


def test_a_delivery_is_signed_and_names_its_event(db: Database, receiver: Receiver) -> None:
    register(db, receiver.url, EventType.RUN_FINISHED, EventType.VERDICT_FAILED)
    run_id = finished_run(db, result_document(passed=False, final=0.02))
    drain(db)
    assert [r["signature_valid"] for r in receiver.requests] == [True, True]
    kinds = {event["type"] for event in receiver.events.values()}
    assert kinds == {"run.finished", "verdict.failed"}
    for event_id, event in receiver.events.items():
        assert event["id"] == event_id and event["run"]["id"] == str(run_id)
    assert all(d.status == DeliveryStatus.DELIVERED for d in deliveries(db))


def test_a_forged_body_fails_verification() -> None:
    body = b'{"id":"1"}'
    header = webhooks.signature(SECRET, body)
    assert webhooks.verify(SECRET, body, header)
    assert not webhooks.verify(SECRET, body + b" ", header)
    assert not webhooks.verify("another-secret-of-16", body, header)


def test_a_failed_try_waits_its_backoff_then_succeeds(db: Database, receiver: Receiver) -> None:
    receiver.script = lambda number, event: 500 if number <= 2 else 204
    register(db, receiver.url, EventType.RUN_FINISHED)
    finished_run(db, result_document())
    slow = DeliveryOptions(
        backoff_base=timedelta(hours=1),
        backoff_max=timedelta(hours=2),
        timeout=timedelta(seconds=5),
    )
    drain(db, slow, rounds=3)
    (delivery,) = deliveries(db)
    # One try, then the backoff holds it back (an hour here): no hammering of a failing receiver.
    assert delivery.attempts == 1 and delivery.status == DeliveryStatus.PENDING
    assert delivery.last_status_code == 500 and "500" in (delivery.last_error or "")
    assert delivery.available_at > datetime.now(UTC) + timedelta(minutes=59)
    with db.transaction() as session:  # the hour has passed
        for row in session.scalars(select(WebhookDelivery)):
            row.available_at = datetime.now(UTC)
    drain(db)
    (delivery,) = deliveries(db)
    assert delivery.status == DeliveryStatus.DELIVERED and delivery.attempts == 3
    assert [r["status"] for r in receiver.requests] == [500, 500, 204]
    assert len({r["event_id"] for r in receiver.requests}) == 1, "every retry keeps the event id"


def test_backoff_doubles_up_to_its_cap() -> None:
    options = DeliveryOptions(backoff_base=timedelta(seconds=2), backoff_max=timedelta(seconds=10))
    assert [options.backoff(n).total_seconds() for n in (1, 2, 3, 4)] == [2, 4, 8, 10]


def test_the_last_attempt_fails_the_delivery(db: Database, receiver: Receiver) -> None:
    receiver.script = lambda number, event: 503
    register(db, receiver.url, EventType.RUN_FINISHED)
    finished_run(db, result_document())
    with db.transaction() as session:
        for row in session.scalars(select(WebhookDelivery)):
            row.max_attempts = 3
    drain(db)
    (delivery,) = deliveries(db)
    assert delivery.status == DeliveryStatus.FAILED and delivery.attempts == 3
    assert len(receiver.requests) == 3


def test_an_unreachable_receiver_is_retried(db: Database, receiver: Receiver) -> None:
    url = receiver.url
    receiver.stop()
    register(db, url, EventType.RUN_FINISHED)
    finished_run(db, result_document())
    drain(db, rounds=2)
    (delivery,) = deliveries(db)
    assert delivery.status == DeliveryStatus.PENDING and delivery.last_status_code is None
    assert "ConnectError" in (delivery.last_error or "")


def test_a_leased_delivery_is_not_sent_twice_at_once(db: Database, receiver: Receiver) -> None:
    register(db, receiver.url, EventType.RUN_FINISHED)
    finished_run(db, result_document())
    first = webhooks.claim_due(db, "worker-a", FAST)
    assert len(first) == 1
    assert webhooks.claim_due(db, "worker-b", FAST) == [], "held under worker-a's lease"
    with db.transaction() as session:  # worker-a dies: its lease lapses
        for row in session.scalars(select(WebhookDelivery)):
            row.lease_expires_at = datetime.now(UTC) - timedelta(seconds=1)
    (second,) = webhooks.claim_due(db, "worker-b", FAST)
    assert second.attempt == 2 and second.event_id == first[0].event_id
    # worker-a's late outcome is refused: worker-b holds it now.
    assert not webhooks.record(db, first[0], 200, None, FAST)
    assert webhooks.record(db, second, 200, None, FAST)


def test_a_deleted_webhook_gets_nothing_more(db: Database, receiver: Receiver) -> None:
    hook_id = register(db, receiver.url, EventType.RUN_FINISHED)
    finished_run(db, result_document())
    with db.transaction() as session:
        hook = registry.get_webhook(session, hook_id)
        assert hook is not None
        registry.delete_webhook(session, hook)
    drain(db)
    finished_run(db, result_document())
    (delivery,) = deliveries(db)
    assert (
        delivery.status == DeliveryStatus.FAILED
        and delivery.last_error == "the webhook was deleted"
    )
    assert receiver.requests == []


def test_the_delivery_loop_stops_when_told(db: Database, receiver: Receiver) -> None:
    register(db, receiver.url, EventType.RUN_FINISHED)
    finished_run(db, result_document())
    stopped = threading.Event()
    loop = threading.Thread(
        target=webhooks.delivery_loop, args=(db, "test", FAST, stopped), daemon=True
    )
    loop.start()
    try:
        for _ in range(200):
            if receiver.events:
                break
            stopped.wait(0.05)
    finally:
        stopped.set()
        loop.join(10)
    assert not loop.is_alive()
    assert len(receiver.events) == 1
    assert json.loads(deliveries(db)[0].body)["type"] == "run.finished"
