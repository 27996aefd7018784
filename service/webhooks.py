"""Webhooks an admin registers, and the listing of their deliveries (the outbox rows with their
outcome). Writing deliveries is `service.outbox`; sending them is `workers.webhooks`."""

from __future__ import annotations

import secrets
import uuid
from datetime import UTC, datetime

from sqlalchemy import select, tuple_
from sqlalchemy.orm import Session

from service.models import DeliveryStatus, EventType, Webhook, WebhookDelivery


def new_secret() -> str:
    return f"whsec_{secrets.token_urlsafe(32)}"


def create_webhook(
    session: Session,
    *,
    url: str,
    events: list[EventType],
    robot_model: str | None,
    secret: str | None,
) -> Webhook:
    hook = Webhook(
        id=uuid.uuid4(),
        url=url,
        secret=secret or new_secret(),
        events=sorted({event.value for event in events}),
        robot_model=robot_model,
        created_at=datetime.now(UTC),
    )
    session.add(hook)
    session.flush()
    return hook


def get_webhook(session: Session, webhook_id: uuid.UUID) -> Webhook | None:
    """A webhook that has not been deleted."""
    hook = session.get(Webhook, webhook_id)
    return hook if hook is not None and hook.deleted_at is None else None


def list_webhooks(session: Session) -> list[Webhook]:
    return list(
        session.scalars(
            select(Webhook)
            .where(Webhook.deleted_at.is_(None))
            .order_by(Webhook.created_at, Webhook.id)
        )
    )


def delete_webhook(session: Session, hook: Webhook) -> None:
    """Deleted webhooks get no new deliveries; the pending ones end `failed` when next due
    (`workers.webhooks`), and the history of the past ones stays listable."""
    hook.deleted_at = datetime.now(UTC)
    session.flush()


def list_deliveries(
    session: Session,
    webhook_id: uuid.UUID,
    *,
    status: DeliveryStatus | None,
    limit: int,
    after: tuple[datetime, uuid.UUID] | None,
) -> list[WebhookDelivery]:
    """The webhook's deliveries, newest first, keyset-paged on (created_at, id)."""
    stmt = (
        select(WebhookDelivery)
        .where(WebhookDelivery.webhook_id == webhook_id)
        .order_by(WebhookDelivery.created_at.desc(), WebhookDelivery.id.desc())
        .limit(limit)
    )
    if status is not None:
        stmt = stmt.where(WebhookDelivery.status == status)
    if after is not None:
        stmt = stmt.where(tuple_(WebhookDelivery.created_at, WebhookDelivery.id) < tuple_(*after))
    return list(session.scalars(stmt))
