"""Webhook delivery from the outbox (`service.outbox`): claim due deliveries with a lease (as runs
are claimed), POST each signed body, and record the outcome, retrying with doubling backoff.

At least once: a worker killed after sending but before recording leaves the lease to lapse, and
the delivery is sent again by whichever worker claims it next; receivers drop the repeat by the
`X-Fleetcal-Event-Id` header. Every write after the claim is conditional on the lease owner.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import threading
import uuid
from dataclasses import dataclass
from datetime import timedelta

import httpx
from sqlalchemy import or_, select
from sqlalchemy.exc import SQLAlchemyError

from service.db import Database
from service.models import DeliveryStatus, Webhook, WebhookDelivery
from service.settings import Settings
from workers.queue import db_now, update_if_leased

log = logging.getLogger(__name__)

SIGNATURE_HEADER = "X-Fleetcal-Signature"
"""`sha256=<hex HMAC-SHA256 of the body with the webhook's secret>`."""
EVENT_ID_HEADER = "X-Fleetcal-Event-Id"
EVENT_HEADER = "X-Fleetcal-Event"
DELIVERY_ID_HEADER = "X-Fleetcal-Delivery-Id"
CLAIM_BATCH = 1
"""One delivery per claim: its lease (at least twice the send timeout) always covers the send."""


def signature(secret: str, body: bytes) -> str:
    return "sha256=" + hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()


def verify(secret: str, body: bytes, header: str) -> bool:
    """What a receiver does with the signature header (constant-time comparison)."""
    return hmac.compare_digest(signature(secret, body), header)


@dataclass(frozen=True)
class DeliveryOptions:
    backoff_base: timedelta = timedelta(seconds=2)
    backoff_max: timedelta = timedelta(minutes=30)
    timeout: timedelta = timedelta(seconds=10)
    lease: timedelta = timedelta(seconds=120)
    """At least twice `timeout`: a live worker never loses the delivery it is sending."""
    poll_interval: timedelta = timedelta(seconds=0.5)

    @classmethod
    def from_settings(cls, settings: Settings) -> DeliveryOptions:
        timeout = timedelta(seconds=settings.webhook_timeout_seconds)
        return cls(
            backoff_base=timedelta(seconds=settings.webhook_backoff_seconds),
            timeout=timeout,
            lease=max(timedelta(seconds=settings.webhook_lease_seconds), timeout * 2),
        )

    def backoff(self, attempts: int) -> timedelta:
        return min(self.backoff_base * (1 << max(attempts - 1, 0)), self.backoff_max)


@dataclass(frozen=True)
class Claimed:
    id: uuid.UUID
    event_id: uuid.UUID
    event: str
    body: str
    url: str | None
    """None: the webhook was deleted since the event."""
    secret: str
    attempt: int
    max_attempts: int
    lease_owner: str


def claim_due(db: Database, owner: str, options: DeliveryOptions) -> list[Claimed]:
    """Lease up to `CLAIM_BATCH` pending deliveries whose time has come (and whose previous
    holder's lease, if any, has lapsed)."""
    with db.transaction() as session:
        now = db_now(session)
        rows = session.execute(
            select(WebhookDelivery, Webhook)
            .join(Webhook, Webhook.id == WebhookDelivery.webhook_id)
            .where(
                WebhookDelivery.status == DeliveryStatus.PENDING,
                WebhookDelivery.available_at <= now,
                or_(
                    WebhookDelivery.lease_expires_at.is_(None),
                    WebhookDelivery.lease_expires_at < now,
                ),
            )
            .order_by(WebhookDelivery.available_at, WebhookDelivery.id)
            .limit(CLAIM_BATCH)
            .with_for_update(skip_locked=True, of=WebhookDelivery)
        ).all()
        claimed = []
        for delivery, hook in rows:
            delivery.attempts += 1
            delivery.lease_owner = f"{owner}#{delivery.attempts}"
            delivery.lease_expires_at = now + options.lease
            delivery.updated_at = now
            claimed.append(
                Claimed(
                    id=delivery.id,
                    event_id=delivery.event_id,
                    event=delivery.event.value,
                    body=delivery.body,
                    url=hook.url if hook.deleted_at is None else None,
                    secret=hook.secret,
                    attempt=delivery.attempts,
                    max_attempts=delivery.max_attempts,
                    lease_owner=delivery.lease_owner,
                )
            )
        return claimed


def send(client: httpx.Client, claimed: Claimed) -> tuple[int | None, str | None]:
    """POST the delivery; (status code, error) with error None on a 2xx."""
    assert claimed.url is not None
    body = claimed.body.encode()
    try:
        response = client.post(
            claimed.url,
            content=body,
            headers={
                "Content-Type": "application/json",
                SIGNATURE_HEADER: signature(claimed.secret, body),
                EVENT_ID_HEADER: str(claimed.event_id),
                EVENT_HEADER: claimed.event,
                DELIVERY_ID_HEADER: str(claimed.id),
                "User-Agent": "fleetcal-webhooks",
            },
        )
    except httpx.HTTPError as err:
        return None, f"{type(err).__name__}: {err}"[:1000]
    if 200 <= response.status_code < 300:
        return response.status_code, None
    return response.status_code, f"the receiver answered {response.status_code}"


def record(
    db: Database,
    claimed: Claimed,
    status_code: int | None,
    error: str | None,
    options: DeliveryOptions,
) -> bool:
    """Store the attempt's outcome; False if the lease was lost meanwhile (nothing written)."""
    with db.transaction() as session:
        now = db_now(session)
        values: dict[str, object] = {
            "last_status_code": status_code,
            "last_error": error,
            "lease_owner": None,
            "lease_expires_at": None,
            "updated_at": now,
        }
        if error is None:
            values |= {"status": DeliveryStatus.DELIVERED, "delivered_at": now}
        elif claimed.attempt >= claimed.max_attempts or claimed.url is None:
            values["status"] = DeliveryStatus.FAILED
        else:
            values["available_at"] = now + options.backoff(claimed.attempt)
        changed = update_if_leased(
            session,
            WebhookDelivery,
            claimed.id,
            DeliveryStatus.PENDING,
            claimed.lease_owner,
            values,
        )
        return changed == 1


def deliver_due(db: Database, client: httpx.Client, owner: str, options: DeliveryOptions) -> int:
    """One round: claim what is due, send it, record each outcome; how many were claimed."""
    claimed = claim_due(db, owner, options)
    for item in claimed:
        if item.url is None:
            outcome: tuple[int | None, str | None] = (None, "the webhook was deleted")
        else:
            outcome = send(client, item)
        if not record(db, item, *outcome, options):
            log.warning("delivery %s: lease lost before its outcome was stored", item.id)
        elif outcome[1] is not None:
            log.warning(
                "delivery %s (event %s) attempt %d/%d: %s",
                item.id,
                item.event_id,
                item.attempt,
                item.max_attempts,
                outcome[1],
            )
    return len(claimed)


def delivery_loop(
    db: Database, owner: str, options: DeliveryOptions, stopped: threading.Event
) -> None:
    """Deliver until `stopped` is set; a database outage only pauses it."""
    with httpx.Client(timeout=options.timeout.total_seconds()) as client:
        while not stopped.is_set():
            try:
                busy = deliver_due(db, client, owner, options) > 0
            except SQLAlchemyError as err:
                log.warning("webhooks: database unavailable (%s)", str(err).splitlines()[0][:200])
                busy = False
            if not busy:
                stopped.wait(options.poll_interval.total_seconds())
