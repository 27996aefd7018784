"""Accept / reject, on both databases: the override scope, a reason, the audit trail, and the
calibration in use following it (the robot's calibration, the fleet, the history)."""

from __future__ import annotations

import uuid

import pytest

from tests.service.conftest import Api, problem_type
from tests.service.documents import result_document
from tests.service.routes.accepted import determined, finished


def _calibration_run(api: Api, robot: str = "R1") -> str | None:
    response = api.client.get(f"/v1/robots/{robot}/calibration", headers=api.headers("read"))
    return response.json()["run_id"] if response.status_code == 200 else None


def test_accepting_a_failed_run_makes_it_the_calibration_in_use(api: Api) -> None:
    good = finished(api, determined())
    failed = finished(api, determined(passed=False, rear_x=-0.43))
    assert _calibration_run(api) == good
    response = api.client.post(
        f"/v1/runs/{failed}/accept",
        json={"reason": "metric error from a person walking by; mount checked by hand"},
        headers=api.headers("override"),
    )
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["passed"] is False and body["accepted"] is True
    (audit,) = body["overrides"]
    assert audit["action"] == "accept" and audit["key_name"] == "line-lead"
    assert audit["reason"].startswith("metric error") and audit["created_at"]
    assert _calibration_run(api) == failed
    fleet = api.client.get("/v1/fleet", headers=api.headers("read")).json()
    assert fleet["items"][0]["latest_calibration"]["run_id"] == failed
    history = api.client.get("/v1/robots/R1/history", headers=api.headers("read")).json()
    assert {(p["run_id"], p["accepted"]) for p in history["items"]} == {
        (good, True),
        (failed, True),
    }
    shown = api.client.get(f"/v1/runs/{failed}", headers=api.headers("read")).json()
    assert shown["overrides"] == body["overrides"]


def test_rejecting_a_passed_run_falls_back_to_the_previous_one(api: Api) -> None:
    first = finished(api, determined())
    second = finished(api, determined(rear_x=-0.45))
    assert _calibration_run(api) == second
    response = api.client.post(
        f"/v1/runs/{second}/reject",
        json={"reason": "the routine ran with a door open"},
        headers=api.headers("admin"),
    )
    assert response.status_code == 200, response.text
    assert response.json()["accepted"] is False
    assert _calibration_run(api) == first
    runs = api.client.get("/v1/runs?robot_id=R1", headers=api.headers("read")).json()["items"]
    assert [(r["id"], r["accepted"]) for r in runs] == [(second, False), (first, True)]
    in_use = api.client.get("/v1/robots/R1/history?accepted=true", headers=api.headers("read"))
    assert {p["run_id"] for p in in_use.json()["items"]} == {first}
    by_verdict = api.client.get("/v1/robots/R1/history?passed=true", headers=api.headers("read"))
    assert {p["run_id"] for p in by_verdict.json()["items"]} == {first, second}
    # And back again: the trail keeps both.
    again = api.client.post(
        f"/v1/runs/{second}/accept",
        json={"reason": "door was closed after all"},
        headers=api.headers("admin"),
    )
    assert [o["action"] for o in again.json()["overrides"]] == ["reject", "accept"]
    assert _calibration_run(api) == second


@pytest.mark.parametrize("key", ["read", "upload_r1"])
def test_an_override_needs_the_override_scope(api: Api, key: str) -> None:
    run = finished(api, determined(passed=False))
    response = api.client.post(
        f"/v1/runs/{run}/accept", json={"reason": "x"}, headers=api.headers(key)
    )
    assert response.status_code == 403 and problem_type(response) == "forbidden"
    assert _calibration_run(api) is None


def test_an_override_without_key_is_401(api: Api) -> None:
    run = finished(api, determined(passed=False))
    response = api.client.post(f"/v1/runs/{run}/accept", json={"reason": "x"})
    assert response.status_code == 401 and problem_type(response) == "unauthenticated"


@pytest.mark.parametrize(
    "body",
    [
        {},
        {"reason": ""},
        {"reason": "x" * 1001},
        {"reason": "a\x00b"},
        {"reason": 3},
        {"reason": "ok", "extra": 1},
    ],
)
def test_an_override_needs_a_reason(api: Api, body: object) -> None:
    run = finished(api, determined(passed=False))
    response = api.client.post(f"/v1/runs/{run}/accept", json=body, headers=api.headers("override"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"


def test_accepting_an_accepted_run_is_a_conflict(api: Api) -> None:
    run = finished(api, determined())
    response = api.client.post(
        f"/v1/runs/{run}/accept", json={"reason": "x"}, headers=api.headers("override")
    )
    assert response.status_code == 409 and problem_type(response) == "override-conflict"
    assert "already accepted" in response.json()["detail"]
    rejected = api.client.post(
        f"/v1/runs/{run}/reject", json={"reason": "x"}, headers=api.headers("override")
    )
    assert rejected.status_code == 200
    twice = api.client.post(
        f"/v1/runs/{run}/reject", json={"reason": "x"}, headers=api.headers("override")
    )
    assert twice.status_code == 409 and "already rejected" in twice.json()["detail"]


def test_an_undetermined_lidar_cannot_be_accepted(api: Api) -> None:
    run = finished(api, result_document(passed=False))  # lidar_left undetermined
    response = api.client.post(
        f"/v1/runs/{run}/accept", json={"reason": "x"}, headers=api.headers("override")
    )
    assert response.status_code == 409 and problem_type(response) == "override-conflict"
    assert "lidar_left" in response.json()["detail"]
    assert _calibration_run(api) is None


def test_a_run_without_result_or_unknown_is_refused(api: Api) -> None:
    queued = api.upload().json()["id"]
    response = api.client.post(
        f"/v1/runs/{queued}/accept", json={"reason": "x"}, headers=api.headers("override")
    )
    assert response.status_code == 409 and problem_type(response) == "run-has-no-result"
    unknown = api.client.post(
        f"/v1/runs/{uuid.uuid4()}/reject", json={"reason": "x"}, headers=api.headers("override")
    )
    assert unknown.status_code == 404 and problem_type(unknown) == "run-not-found"
    bad = api.client.post(
        "/v1/runs/not-a-uuid/reject", json={"reason": "x"}, headers=api.headers("override")
    )
    assert bad.status_code == 422 and problem_type(bad) == "invalid-request"
