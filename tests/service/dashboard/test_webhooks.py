"""The webhooks page in headless Chromium (webhooks.js), for admin keys: each webhook's deliveries
with their status, attempts, the receiver's last answer and the last error, as the API lists them.
The deliveries are real: the seeded fleet's events sent by the workers' code to two receivers on
loopback, one answering 200 and one 503."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import update

from service import webhooks
from service.db import Database
from service.models import EventType, WebhookDelivery
from service.settings import Settings
from tests.service.dashboard.browser import api_json, open_page, screenshot, sign_in, wait_for
from tests.service.dashboard.conftest import FleetApps, LiveApp
from tests.service.webhook_receiver import Receiver
from workers.webhooks import DeliveryOptions, deliver_due


@pytest.fixture(scope="module")
def hooks(fleet_apps: FleetApps) -> Iterator[tuple[LiveApp, dict[str, uuid.UUID]]]:
    """The fleet with webhook `up` (every event, a receiver answering 200) and `down` (failed
    verdicts and runs, a receiver answering 503); R2's failed run had one try to give `down`."""
    receivers = {
        "up": Receiver(secret="whsec_up_0123456789abcdef").start(),
        "down": Receiver(secret="whsec_down_0123456789abcdef", script=lambda n, e: 503).start(),
    }
    ids: dict[str, uuid.UUID] = {}

    def register(db: Database) -> None:
        with db.transaction() as session:
            for name, events in (
                ("up", list(EventType)),
                ("down", [EventType.VERDICT_FAILED, EventType.RUN_FAILED]),
            ):
                ids[name] = webhooks.create_webhook(
                    session,
                    url=receivers[name].url,
                    events=events,
                    robot_model=None,
                    secret=receivers[name].secret,
                ).id

    try:
        with fleet_apps("hooks", register) as app:
            assert app.data_dir is not None
            db = Database.from_settings(Settings(data_dir=app.data_dir))
            with db.transaction() as session:
                session.execute(
                    update(WebhookDelivery)
                    .where(
                        WebhookDelivery.webhook_id == ids["down"],
                        WebhookDelivery.event == EventType.RUN_FAILED,
                    )
                    .values(max_attempts=1)
                )
            options = DeliveryOptions(backoff_base=timedelta(hours=1))  # one try each here
            with httpx.Client() as client:
                while deliver_due(db, client, "dashboard-test", options):
                    pass
            db.dispose()
            yield app, ids
    finally:
        for receiver in receivers.values():
            receiver.stop()


def deliveries(app: LiveApp, webhook_id: uuid.UUID, query: str = "") -> list[dict[str, Any]]:
    path = f"/v1/webhooks/{webhook_id}/deliveries?limit=500{query}"
    items: list[dict[str, Any]] = api_json(app.url, app.keys["admin"], path)["items"]
    return items


def shown_rows(browser: Any) -> dict[str, dict[str, str]]:
    rows = wait_for(browser, "#deliveries tbody tr")

    def cell(row: Any, name: str) -> str:
        return str(row.find_element("css selector", f"td.{name}").text)

    return {
        row.get_attribute("data-delivery-id"): {
            "status": row.get_attribute("data-status"),
            "attempts": cell(row, "attempts"),
            "last_status": cell(row, "last-status"),
            "last_error": cell(row, "last-error"),
        }
        for row in rows
    }


def expected_rows(items: list[dict[str, Any]]) -> dict[str, dict[str, str]]:
    return {
        d["id"]: {
            "status": d["status"],
            "attempts": f"{d['attempts']} of {d['max_attempts']}",
            "last_status": "–" if d["last_status_code"] is None else str(d["last_status_code"]),
            "last_error": d["last_error"] or "–",
        }
        for d in items
    }


def test_an_admin_sees_each_deliverys_status_attempts_and_last_error(
    browser: Any, hooks: tuple[LiveApp, dict[str, uuid.UUID]], artifacts_dir: Path
) -> None:
    app, ids = hooks
    sign_in(browser, app.url, app.keys["admin"])
    link = wait_for(browser, "#nav-webhooks")[0]
    assert link.is_displayed()
    link.click()
    rows = wait_for(browser, "#webhooks tbody tr", count=2)
    assert [row.get_attribute("data-webhook-id") for row in rows] == [
        str(ids["up"]),
        str(ids["down"]),
    ]

    down = deliveries(app, ids["down"])
    open_page(browser, app.url, f"/webhooks/{ids['down']}")
    shown = shown_rows(browser)
    assert shown == expected_rows(down)
    # Three failed verdicts wait for their next try; R2's failed run had its one try.
    assert sorted(row["status"] for row in shown.values()) == [
        "failed",
        "pending",
        "pending",
        "pending",
    ]
    assert {row["last_error"] for row in shown.values()} == {"the receiver answered 503"}
    assert {row["last_status"] for row in shown.values()} == {"503"}
    screenshot(browser, artifacts_dir, "webhook-deliveries")

    from selenium.webdriver.support.ui import Select

    Select(wait_for(browser, "#delivery-status")[0]).select_by_value("failed")
    wait_for(browser, "#deliveries tbody tr")
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, 30).until(
        lambda d: len(d.find_elements("css selector", "#deliveries tbody tr")) == 1
    )
    assert shown_rows(browser) == expected_rows(deliveries(app, ids["down"], "&status=failed"))


def test_the_live_receivers_deliveries_are_all_delivered(
    browser: Any, hooks: tuple[LiveApp, dict[str, uuid.UUID]]
) -> None:
    app, ids = hooks
    sign_in(browser, app.url, app.keys["admin"])
    up = deliveries(app, ids["up"])
    open_page(browser, app.url, f"/webhooks/{ids['up']}")
    shown = shown_rows(browser)
    assert shown == expected_rows(up)
    # Seven results, three failed verdicts, one drift over the limit, one failed run.
    assert len(shown) == 12 and {row["status"] for row in shown.values()} == {"delivered"}


def test_a_key_that_is_not_admin_gets_no_webhooks(
    browser: Any, hooks: tuple[LiveApp, dict[str, uuid.UUID]]
) -> None:
    app, _ = hooks
    sign_in(browser, app.url, app.keys["operator"])
    assert not browser.find_element("id", "nav-webhooks").is_displayed()
    open_page(browser, app.url, "/webhooks")
    assert "needs a key with the 'admin' scope" in wait_for(browser, "#page-error")[0].text
