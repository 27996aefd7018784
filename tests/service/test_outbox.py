"""The outbox: the events a stored result or a failed run raise become delivery rows in the same
transaction, one per subscribed webhook (and robot model), sharing the event's id."""

from __future__ import annotations

import json
import uuid
from collections.abc import Iterator

import pytest
from sqlalchemy import select

from service import outbox, repository, webhooks
from service.db import Database
from service.models import EventType, WebhookDelivery
from service.settings import Settings
from tests.service.documents import result_document
from tests.service.uploads import new_upload


@pytest.fixture
def db(settings: Settings) -> Iterator[Database]:
    database = Database.from_settings(settings)
    yield database
    database.dispose()


def _run(db: Database, robot_id: str = "R1", model: str | None = None) -> uuid.UUID:
    run_id = uuid.uuid4()
    with db.transaction() as session:
        repository.put_robot(session, robot_id, model=model, metadata={})
        repository.record_upload(session, new_upload(robot_id, run_id=run_id), create_robot=True)
    return run_id


def _hook(db: Database, *events: EventType, robot_model: str | None = None) -> uuid.UUID:
    with db.transaction() as session:
        return webhooks.create_webhook(
            session,
            url="http://127.0.0.1:9/hook",
            events=list(events),
            robot_model=robot_model,
            secret=None,
        ).id


def _deliveries(db: Database) -> list[WebhookDelivery]:
    with db.session() as session:
        return list(session.scalars(select(WebhookDelivery)))


def test_a_failed_verdict_raises_finished_and_failed(db: Database) -> None:
    both = _hook(db, EventType.RUN_FINISHED, EventType.VERDICT_FAILED)
    only_failed = _hook(db, EventType.VERDICT_FAILED)
    run_id = _run(db)
    with db.transaction() as session:
        repository.store_result(session, run_id, result_document(passed=False, final=0.02))
    rows = _deliveries(db)
    assert sorted((r.webhook_id == both, r.event.value) for r in rows) == [
        (False, "verdict.failed"),
        (True, "run.finished"),
        (True, "verdict.failed"),
    ]
    failed = [r for r in rows if r.event == EventType.VERDICT_FAILED]
    assert failed[0].event_id == failed[1].event_id, "one event, one id, for every webhook"
    assert {r.webhook_id for r in failed} == {both, only_failed}
    body = json.loads(failed[0].body)
    assert body["type"] == "verdict.failed" and body["run"]["id"] == str(run_id)
    assert [c["name"] for c in body["data"]["failed_checks"]] == [
        "metric_error",
        "lidar_left determined",
    ]


def test_drift_over_the_limit_is_its_own_event(db: Database) -> None:
    _hook(db, EventType.DRIFT_EXCEEDED)
    run_id = _run(db)
    document = result_document(passed=False)
    document["verdict"]["checks"].append(
        {"name": "drift_translation:lidar_rear", "value": 0.03, "limit": 0.01, "passed": False}
    )
    document["drift"] = {"against": "last_accepted", "lidars": {}, "missing": []}
    with db.transaction() as session:
        repository.store_result(session, run_id, document)
    (row,) = _deliveries(db)
    data = json.loads(row.body)["data"]
    assert [c["name"] for c in data["failed_checks"]] == ["drift_translation:lidar_rear"]


def test_a_failed_run_raises_run_failed(db: Database) -> None:
    _hook(db, EventType.RUN_FAILED, EventType.RUN_FINISHED)
    run_id = _run(db)
    problem = {"type": "urn:fleetcal:problem:x", "title": "X", "status": 422, "detail": "bad"}
    with db.transaction() as session:
        repository.fail_run(session, run_id, problem)
    (row,) = _deliveries(db)
    assert row.event == EventType.RUN_FAILED
    assert json.loads(row.body)["data"]["error"]["detail"] == "bad"


def test_a_webhook_for_one_model_hears_only_its_robots(db: Database) -> None:
    _hook(db, EventType.RUN_FINISHED, robot_model="amr-2")
    other = _run(db, "R1", model="amr-1")
    mine = _run(db, "R2", model="amr-2")
    with db.transaction() as session:
        repository.store_result(session, other, result_document())
        repository.store_result(session, mine, result_document())
    assert [r.run_id for r in _deliveries(db)] == [mine]


def test_events_roll_back_with_their_transaction(db: Database) -> None:
    _hook(db, EventType.RUN_FINISHED)
    run_id = _run(db)
    with pytest.raises(RuntimeError, match="after the result"), db.transaction() as session:
        repository.store_result(session, run_id, result_document())
        assert len(list(session.scalars(select(WebhookDelivery)))) == 1
        raise RuntimeError("the worker died after the result, before the commit")
    assert _deliveries(db) == []


def test_no_webhook_no_rows(db: Database) -> None:
    run_id = _run(db)
    with db.transaction() as session:
        result = repository.store_result(session, run_id, result_document())
        assert outbox.result_events(result)[0][0] == EventType.RUN_FINISHED
    assert _deliveries(db) == []
