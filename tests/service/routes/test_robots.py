"""Robots: listing, detail, admin registration, latest accepted calibration, extrinsic history."""

from __future__ import annotations

import uuid

import pytest

from service import repository
from tests.service.conftest import Api, problem_type
from tests.service.documents import result_document


def _finish(api: Api, run_id: str, **document: object) -> None:
    with api.services.db.transaction() as session:
        repository.store_result(session, uuid.UUID(run_id), result_document(**document))  # type: ignore[arg-type]


def test_list_robots_pages_by_id(api: Api) -> None:
    for robot in ("R3", "R1", "R2"):
        api.upload(robot)
    first = api.client.get("/v1/robots?limit=2", headers=api.headers("read")).json()
    assert [r["id"] for r in first["items"]] == ["R1", "R2"]
    second = api.client.get(
        f"/v1/robots?limit=2&cursor={first['next_cursor']}", headers=api.headers("read")
    ).json()
    assert [r["id"] for r in second["items"]] == ["R3"] and second["next_cursor"] is None
    response = api.client.get(
        f"/v1/robots?cursor={first['next_cursor']}x", headers=api.headers("read")
    )
    assert response.status_code == 400 and problem_type(response) == "invalid-cursor"


def test_put_robot_registers_then_updates(api: Api) -> None:
    created = api.client.put(
        "/v1/robots/R9",
        json={"model": "mk2", "metadata": {"site": "Lyon"}},
        headers=api.headers("admin"),
    )
    assert created.status_code == 201
    assert created.json()["model"] == "mk2" and created.json()["metadata"] == {"site": "Lyon"}
    updated = api.client.put("/v1/robots/R9", json={"model": "mk3"}, headers=api.headers("admin"))
    assert updated.status_code == 200 and updated.json()["model"] == "mk3"
    assert updated.json()["metadata"] == {}
    assert updated.json()["created_at"] == created.json()["created_at"]


@pytest.mark.parametrize("body", [{"model": "a b"}, {"colour": "red"}, {"metadata": [1]}, "x"])
def test_put_robot_refuses_bad_bodies(api: Api, body: object) -> None:
    response = api.client.put("/v1/robots/R9", json=body, headers=api.headers("admin"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"
    assert api.client.get("/v1/robots/R9", headers=api.headers("read")).status_code == 404


def test_get_robot_shows_profile_and_latest_run(api: Api) -> None:
    api.client.put(
        "/v1/tolerance-profiles/mk2-strict",
        json={"robot_model": "mk2", "limits": {"max_metric_error_m": 0.003}},
        headers=api.headers("admin"),
    )
    api.client.put("/v1/robots/R1", json={"model": "mk2"}, headers=api.headers("admin"))
    api.upload("R1")
    latest = api.upload("R1").json()
    robot = api.client.get("/v1/robots/R1", headers=api.headers("read")).json()
    assert robot["tolerance_profile"] == "mk2-strict"
    assert robot["latest_run"]["id"] == latest["id"]
    response = api.client.get("/v1/robots/ghost", headers=api.headers("read"))
    assert response.status_code == 404 and problem_type(response) == "robot-not-found"


def test_calibration_is_the_latest_passed_result(api: Api) -> None:
    response = api.client.get("/v1/robots/R1/calibration", headers=api.headers("read"))
    assert response.status_code == 404 and problem_type(response) == "robot-not-found"
    old, new, rejected = (api.upload("R1").json()["id"] for _ in range(3))
    response = api.client.get("/v1/robots/R1/calibration", headers=api.headers("read"))
    assert response.status_code == 404 and problem_type(response) == "no-calibration"

    _finish(api, old, rear_x=-0.40)
    _finish(api, new, rear_x=-0.41)
    _finish(api, rejected, passed=False, final=0.02, rear_x=-0.55)
    calibration = api.client.get("/v1/robots/R1/calibration", headers=api.headers("read")).json()
    assert calibration["run_id"] == new
    assert set(calibration["lidars"]) == {"lidar_front", "lidar_rear"}
    rear = calibration["lidars"]["lidar_rear"]
    assert rear["translation"] == [-0.41, 0.004, 0.618] and not rear["is_reference"]
    assert calibration["lidars"]["lidar_front"]["is_reference"]
    assert (
        calibration["metric_error_final"] == 0.0012 and calibration["pipeline_version"] == "0.1.0"
    )
    assert calibration["result"]["lidars"]["lidar_left"]["calibrated"] is None


def test_history_is_a_per_lidar_series_oldest_first(api: Api) -> None:
    runs = [api.upload("R1").json()["id"] for _ in range(4)]
    rear_xs = [-0.40, -0.41, -0.42, -0.43]
    for index, run_id in enumerate(runs):
        _finish(api, run_id, rear_x=rear_xs[index], passed=index != 2)
    api.upload("R2")

    def history(query: str = "") -> dict:  # type: ignore[type-arg]
        response = api.client.get(f"/v1/robots/R1/history?{query}", headers=api.headers("read"))
        assert response.status_code == 200, response.text
        return response.json()  # type: ignore[no-any-return]

    everything = history()
    assert len(everything["items"]) == 8 and everything["next_cursor"] is None
    rear = history("frame=lidar_rear")["items"]
    assert [p["run_id"] for p in rear] == runs
    assert [p["translation"][0] for p in rear] == rear_xs
    assert [p["passed"] for p in rear] == [True, True, False, True]
    accepted = history("frame=lidar_rear&passed=true")["items"]
    assert [p["run_id"] for p in accepted] == [runs[0], runs[1], runs[3]]
    assert history("frame=lidar_left")["items"] == []  # never determined: no points

    pages, cursor = [], None
    while True:
        page = history("frame=lidar_rear&limit=3" + (f"&cursor={cursor}" if cursor else ""))
        pages.append([p["run_id"] for p in page["items"]])
        cursor = page["next_cursor"]
        if cursor is None:
            break
    assert pages == [runs[:3], runs[3:]]

    response = api.client.get(
        "/v1/robots/R1/history?cursor=WyJydW5zIiwiYSIsImIiXQ", headers=api.headers("read")
    )
    assert response.status_code == 400 and problem_type(response) == "invalid-cursor"
    response = api.client.get("/v1/robots/R1/history?limit=10001", headers=api.headers("read"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"
    response = api.client.get("/v1/robots/ghost/history", headers=api.headers("read"))
    assert response.status_code == 404 and problem_type(response) == "robot-not-found"
