"""Accept / reject on a run's page in headless Chromium (overrides.js): an operator accepts a failed
calibration and rejects a passed one, each with a reason; the page, the audit trail, the robot's
calibration in use and the API all follow. A read key is told which key it needs, and the API's
refusals are shown. These tests change their fleet: it is their own, not the shared `live_app`."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.service.dashboard.browser import api_json, open_page, screenshot, sign_in, wait_for
from tests.service.dashboard.conftest import FleetApps, LiveApp


@pytest.fixture(scope="module")
def operator_app(fleet_apps: FleetApps) -> Iterator[LiveApp]:
    with fleet_apps("operator") as app:
        yield app


def run_of(app: LiveApp, run_id: object) -> Any:
    return api_json(app.url, app.read_key, f"/v1/runs/{run_id}")


def accepted_badge(browser: Any) -> Any:
    return wait_for(browser, "#accepted .accepted-badge")[0]


def decide(browser: Any, button: str, reason: str) -> None:
    """Type `reason` and press `button` (#accept-run or #reject-run)."""
    field = wait_for(browser, "#override-reason")[0]
    field.clear()
    field.send_keys(reason)
    wait_for(browser, button)[0].click()


def test_a_read_key_sees_the_decision_but_is_told_it_may_not_make_it(
    browser: Any, operator_app: LiveApp
) -> None:
    sign_in(browser, operator_app.url, operator_app.read_key)
    open_page(browser, operator_app.url, f"/runs/{operator_app.fleet.diverged}")
    refused = wait_for(browser, "#override-refused")[0]
    assert "needs a key with the override scope" in refused.text
    assert "--scope override" in refused.text
    assert not browser.find_elements("css selector", "#override-form, #accept-run, #reject-run")
    badge = accepted_badge(browser)
    assert (badge.text, badge.get_attribute("data-accepted")) == ("not accepted", "false")
    assert "failed its verdict and is not accepted" in wait_for(browser, "#override-state")[0].text
    # No admin: no webhooks in the header.
    assert not browser.find_element("id", "nav-webhooks").is_displayed()
    assert browser.find_element("id", "key-name").text == "key: dashboard read"


def test_an_operator_accepts_a_failed_calibration_with_a_reason(
    browser: Any, operator_app: LiveApp, artifacts_dir: Path
) -> None:
    fleet, run = operator_app.fleet, operator_app.fleet.diverged
    before = api_json(operator_app.url, operator_app.read_key, "/v1/robots/R4/calibration")
    assert before["run_id"] == str(fleet.r4_accepted[1])
    sign_in(browser, operator_app.url, operator_app.keys["operator"])
    open_page(browser, operator_app.url, f"/runs/{run}")
    assert not browser.find_elements("css selector", "#reject-run")
    # No reason, no call: the form says what is missing.
    wait_for(browser, "#accept-run")[0].click()
    assert "Give a reason" in wait_for(browser, "#override-error")[0].text
    assert run_of(operator_app, run)["overrides"] == []

    reason = "rear mount checked with a gauge; the optimisation ran on a crowded floor"
    decide(browser, "#accept-run", reason)
    rows = wait_for(browser, "#override-trail tbody tr")
    assert len(rows) == 1 and rows[0].get_attribute("data-action") == "accept"
    assert reason in rows[0].text and "dashboard operator" in rows[0].text
    badge = accepted_badge(browser)
    assert badge.text == "accepted by an operator"
    assert badge.get_attribute("data-overridden") == "true"
    # The verdict is what the pipeline said; only whether the calibration is used changed.
    assert wait_for(browser, "#verdict [data-verdict]")[0].get_attribute("data-verdict") == "failed"
    assert wait_for(browser, "#reject-run") and not browser.find_elements(
        "css selector", "#accept-run"
    )
    screenshot(browser, artifacts_dir, "run-accepted")

    stored = run_of(operator_app, run)
    assert stored["accepted"] is True and stored["passed"] is False
    assert [(o["action"], o["reason"], o["key_name"]) for o in stored["overrides"]] == [
        ("accept", reason, "dashboard operator")
    ]
    # R4's calibration in use is now the accepted one, on the robot page as in the API.
    open_page(browser, operator_app.url, "/robots/R4")
    in_use = wait_for(browser, "#calibration-in-use")[0]
    assert in_use.get_attribute("data-run-id") == str(run)
    calibration = api_json(operator_app.url, operator_app.read_key, "/v1/robots/R4/calibration")
    assert calibration["run_id"] == str(run)
    row = wait_for(browser, f'table.runs tr[data-run-id="{run}"]')[0]
    assert "accepted by an operator" in row.text


def test_an_operator_rejects_a_passed_calibration_and_the_robot_falls_back(
    browser: Any, operator_app: LiveApp
) -> None:
    fleet = operator_app.fleet
    sign_in(browser, operator_app.url, operator_app.keys["operator"])
    open_page(browser, operator_app.url, "/robots/R1")
    assert wait_for(browser, "#calibration-in-use")[0].get_attribute("data-run-id") == str(
        fleet.repaired
    )
    open_page(browser, operator_app.url, f"/runs/{fleet.repaired}")
    assert accepted_badge(browser).text == "accepted"
    decide(browser, "#reject-run", "the routine ran with the loading door open")
    wait_for(browser, "#override-trail tbody tr")
    badge = accepted_badge(browser)
    assert (badge.text, badge.get_attribute("data-accepted")) == (
        "rejected by an operator",
        "false",
    )
    assert "keeps its previous accepted calibration" in wait_for(browser, "#override-state")[0].text
    assert run_of(operator_app, fleet.repaired)["accepted"] is False
    # The hit mount's run failed: R1 falls back to its end-of-line calibration.
    open_page(browser, operator_app.url, "/robots/R1")
    assert wait_for(browser, "#calibration-in-use")[0].get_attribute("data-run-id") == str(
        fleet.end_of_line
    )
    calibration = api_json(operator_app.url, operator_app.read_key, "/v1/robots/R1/calibration")
    assert calibration["run_id"] == str(fleet.end_of_line)


def test_the_apis_refusal_is_shown_and_nothing_changes(browser: Any, operator_app: LiveApp) -> None:
    run = operator_app.fleet.undetermined  # the rear LiDAR has no calibrated pose to use
    sign_in(browser, operator_app.url, operator_app.keys["operator"])
    open_page(browser, operator_app.url, f"/runs/{run}")
    decide(browser, "#accept-run", "accept it anyway")
    error = wait_for(browser, "#override-error")[0]
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, 30).until(lambda _: "refused" in error.text)
    assert "could not determine lidar_rear" in error.text
    assert "record the routine again" in error.text
    assert wait_for(browser, "#accept-run")[0].is_enabled()
    assert not browser.find_elements("css selector", "#override-trail")
    assert run_of(operator_app, run)["overrides"] == []
