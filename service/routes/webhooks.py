"""Webhooks (admin): register, list, delete, and the deliveries of each with their outcome."""

from __future__ import annotations

import json
import uuid
from typing import Annotated

from fastapi import APIRouter, Query, Response
from sqlalchemy.orm import Session

from service import webhooks
from service.deps import AdminKey, SessionDep, WriteSessionDep
from service.models import DeliveryStatus, Webhook, WebhookDelivery
from service.pagination import (
    PAGE_SIZE_DEFAULT,
    PAGE_SIZE_MAX,
    cursor_datetime,
    cursor_uuid,
    decode_cursor,
    encode_cursor,
)
from service.parameters import CursorQuery
from service.problem_details import PROBLEM_RESPONSES, WebhookNotFound
from service.schemas import (
    DeliveryPage,
    DeliveryPublic,
    WebhookCreated,
    WebhookIn,
    WebhookPage,
    WebhookPublic,
)

router = APIRouter(prefix="/v1/webhooks", tags=["webhooks"], responses=PROBLEM_RESPONSES)

_DELIVERY_HEADERS = """\
Each delivery is a POST of a JSON event (`id`, `type`, `occurred_at`, `robot`, `run`, `data`) with
headers `X-Fleetcal-Event-Id` (the same on every retry: drop repeats by it), `X-Fleetcal-Event`,
`X-Fleetcal-Delivery-Id` and `X-Fleetcal-Signature: sha256=<hex HMAC-SHA256 of the body with the
webhook's secret>`. Any 2xx answer counts as delivered; anything else is retried with doubling
backoff, at least once per event."""


@router.post(
    "",
    status_code=201,
    summary="Register a webhook (admin)",
    description=_DELIVERY_HEADERS,
)
def create_webhook(body: WebhookIn, _: AdminKey, session: WriteSessionDep) -> WebhookCreated:
    hook = webhooks.create_webhook(
        session,
        url=str(body.url),
        events=body.events,
        robot_model=body.robot_model,
        secret=body.secret,
    )
    session.commit()
    return WebhookCreated(**webhook_public(hook).model_dump(), secret=hook.secret)


@router.get("", summary="The registered webhooks (admin)")
def list_webhooks(_: AdminKey, session: SessionDep) -> WebhookPage:
    return WebhookPage(items=[webhook_public(hook) for hook in webhooks.list_webhooks(session)])


@router.get("/{webhook_id}", summary="A webhook (admin)")
def get_webhook(webhook_id: uuid.UUID, _: AdminKey, session: SessionDep) -> WebhookPublic:
    return webhook_public(_webhook(session, webhook_id))


@router.delete("/{webhook_id}", status_code=204, summary="Delete a webhook (admin)")
def delete_webhook(webhook_id: uuid.UUID, _: AdminKey, session: WriteSessionDep) -> Response:
    webhooks.delete_webhook(session, _webhook(session, webhook_id))
    session.commit()
    return Response(status_code=204)


@router.get(
    "/{webhook_id}/deliveries", summary="A webhook's deliveries and their outcome, newest first"
)
def list_deliveries(
    webhook_id: uuid.UUID,
    _: AdminKey,
    session: SessionDep,
    status: DeliveryStatus | None = None,
    limit: Annotated[int, Query(ge=1, le=PAGE_SIZE_MAX)] = PAGE_SIZE_DEFAULT,
    cursor: CursorQuery = None,
) -> DeliveryPage:
    _webhook(session, webhook_id)
    after = None
    if cursor is not None:
        created, delivery_id = decode_cursor(cursor, "deliveries", cursor_datetime, cursor_uuid)
        after = (created, delivery_id)
    rows = webhooks.list_deliveries(
        session, webhook_id, status=status, limit=limit + 1, after=after
    )
    next_cursor = None
    if len(rows) > limit:
        last = rows[limit - 1]
        next_cursor = encode_cursor("deliveries", last.created_at, last.id)
    return DeliveryPage(
        items=[delivery_public(row) for row in rows[:limit]], next_cursor=next_cursor
    )


def webhook_public(hook: Webhook) -> WebhookPublic:
    return WebhookPublic.model_validate(hook, from_attributes=True)


def delivery_public(row: WebhookDelivery) -> DeliveryPublic:
    return DeliveryPublic(
        id=row.id,
        event_id=row.event_id,
        event=row.event,
        run_id=row.run_id,
        robot_id=row.robot_id,
        status=row.status,
        attempts=row.attempts,
        max_attempts=row.max_attempts,
        available_at=row.available_at,
        last_status_code=row.last_status_code,
        last_error=row.last_error,
        created_at=row.created_at,
        delivered_at=row.delivered_at,
        payload=json.loads(row.body),
    )


def _webhook(session: Session, webhook_id: uuid.UUID) -> Webhook:
    hook = webhooks.get_webhook(session, webhook_id)
    if hook is None:
        raise WebhookNotFound(f"no webhook {webhook_id}; GET /v1/webhooks lists them")
    return hook
