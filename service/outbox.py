"""The webhook outbox: events become delivery rows in the transaction that caused them (a result
stored, a run failed), one per matching webhook, all with the event's id; the workers send them
(`workers.webhooks`). An event and its deliveries commit together or not at all."""

from __future__ import annotations

import json
import uuid
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from service.models import (
    DeliveryStatus,
    EventType,
    Result,
    Robot,
    Run,
    Webhook,
    WebhookDelivery,
)

DRIFT_CHECK_PREFIX = "drift_"
"""`pipeline.verdict` names its checks against the last accepted calibration `drift_*:<frame>`."""
DEFAULT_MAX_ATTEMPTS = 12
"""Tries per delivery; with the workers' doubling backoff (capped) that spans hours, enough for a
receiver restarted or redeployed, not so long that a dead URL is retried forever."""


def result_events(result: Result) -> list[tuple[EventType, dict[str, Any]]]:
    """The events a stored result raises, each with its `data`."""
    checks = result.document.get("verdict", {}).get("checks", [])
    failed = [check for check in checks if not check.get("passed", False)]
    events: list[tuple[EventType, dict[str, Any]]] = [
        (
            EventType.RUN_FINISHED,
            {"passed": result.passed, "metric_error_final": result.metric_error_final},
        )
    ]
    if not result.passed:
        events.append((EventType.VERDICT_FAILED, {"failed_checks": failed}))
    drifted = [
        check for check in failed if str(check.get("name", "")).startswith(DRIFT_CHECK_PREFIX)
    ]
    if drifted:
        events.append(
            (
                EventType.DRIFT_EXCEEDED,
                {"failed_checks": drifted, "drift": result.document.get("drift")},
            )
        )
    return events


def enqueue_events(
    session: Session,
    run: Run,
    events: list[tuple[EventType, dict[str, Any]]],
    *,
    max_attempts: int = DEFAULT_MAX_ATTEMPTS,
) -> list[WebhookDelivery]:
    """One delivery row per event and live webhook subscribed to it (and to the robot's model,
    if the webhook names one), in `session`'s transaction."""
    if not events:
        return []
    robot = session.get(Robot, run.robot_id)
    model = robot.model if robot is not None else None
    hooks = list(session.scalars(select(Webhook).where(Webhook.deleted_at.is_(None))))
    now = datetime.now(UTC)
    deliveries = []
    for event, data in events:
        subscribed = [
            hook
            for hook in hooks
            if event.value in hook.events and hook.robot_model in (None, model)
        ]
        if not subscribed:
            continue
        event_id = uuid.uuid4()
        body = _event_body(event_id, event, data, run, model, now)
        for hook in subscribed:
            delivery = WebhookDelivery(
                id=uuid.uuid4(),
                webhook_id=hook.id,
                event_id=event_id,
                event=event,
                run_id=run.id,
                robot_id=run.robot_id,
                body=body,
                status=DeliveryStatus.PENDING,
                attempts=0,
                max_attempts=max_attempts,
                available_at=now,
                created_at=now,
                updated_at=now,
            )
            session.add(delivery)
            deliveries.append(delivery)
    return deliveries


def _event_body(
    event_id: uuid.UUID,
    event: EventType,
    data: dict[str, Any],
    run: Run,
    model: str | None,
    now: datetime,
) -> str:
    """The JSON every delivery of one event sends: compact, keys sorted (what the signature of
    `workers.webhooks` covers byte for byte)."""
    return json.dumps(
        {
            "id": str(event_id),
            "type": event.value,
            "occurred_at": now.isoformat(),
            "robot": {"id": run.robot_id, "model": model},
            "run": {
                "id": str(run.id),
                "kind": run.kind.value,
                "status": run.status.value,
                "attempts": run.attempts,
                "url": f"/v1/runs/{run.id}",
            },
            "data": data,
        },
        sort_keys=True,
        separators=(",", ":"),
        allow_nan=False,
    )
