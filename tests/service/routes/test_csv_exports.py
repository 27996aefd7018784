"""CSV exports, on both databases, read back with the standard library's csv reader: a robot's
history and the fleet's calibrations in use."""

from __future__ import annotations

import csv
import io

import pytest

from service.routes import csv_exports
from tests.service.conftest import Api, problem_type
from tests.service.routes.accepted import determined, finished


def _rows(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


def test_history_csv_has_a_row_per_lidar_and_run(api: Api) -> None:
    first = finished(api, determined())
    second = finished(api, determined(passed=False, rear_x=-0.45))
    response = api.client.get("/v1/robots/R1/history.csv", headers=api.headers("read"))
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/csv")
    assert 'filename="R1-history.csv"' in response.headers["content-disposition"]
    rows = _rows(response.text)
    assert [(r["run_id"], r["frame"], r["passed"], r["accepted"]) for r in rows] == [
        (first, "lidar_front", "True", "True"),
        (first, "lidar_rear", "True", "True"),
        (second, "lidar_front", "False", "False"),
        (second, "lidar_rear", "False", "False"),
    ]
    assert float(rows[3]["tx"]) == -0.45 and float(rows[3]["qw"]) == 0.0009
    accepted = _rows(
        api.client.get("/v1/robots/R1/history.csv?accepted=true", headers=api.headers("read")).text
    )
    assert {r["run_id"] for r in accepted} == {first}


def test_fleet_csv_holds_each_robots_calibration_in_use(api: Api) -> None:
    r1 = finished(api, determined())
    finished(api, determined(passed=False), robot="R2")
    api.client.put("/v1/robots/R3", json={"model": "amr"}, headers=api.headers("admin"))
    response = api.client.get("/v1/fleet/calibrations.csv", headers=api.headers("read"))
    assert response.status_code == 200, response.text
    rows = _rows(response.text)
    assert [(r["robot_id"], r["run_id"], r["frame"]) for r in rows] == [
        ("R1", r1, "lidar_front"),
        ("R1", r1, "lidar_rear"),
        ("R2", "", ""),
        ("R3", "", ""),
    ]
    assert rows[3]["model"] == "amr" and float(rows[1]["tx"]) == -0.41


def test_csv_errors_are_problems(api: Api) -> None:
    cases = [
        ("/v1/robots/nobody/history.csv", "read", 404, "robot-not-found"),
        ("/v1/robots/R1/history.csv?since=yesterday", "read", 422, "invalid-request"),
        ("/v1/robots/R2/history.csv", "upload_r1", 403, "forbidden"),
        ("/v1/fleet/calibrations.csv", "upload_r1", 403, "forbidden"),
    ]
    finished(api, determined(), robot="R2")
    for path, key, status, slug in cases:
        response = api.client.get(path, headers=api.headers(key))
        assert (response.status_code, problem_type(response)) == (status, slug), path


def test_both_csvs_follow_an_operators_accept_and_reject(api: Api) -> None:
    good = finished(api, determined())
    failed = finished(api, determined(passed=False, rear_x=-0.43))
    override = api.headers("override")
    accepted = api.client.post(f"/v1/runs/{failed}/accept", json={"reason": "x"}, headers=override)
    assert accepted.status_code == 200, accepted.text

    def csvs() -> tuple[list[dict[str, str]], list[dict[str, str]]]:
        read = api.headers("read")
        history = api.client.get("/v1/robots/R1/history.csv", headers=read)
        fleet = api.client.get("/v1/fleet/calibrations.csv", headers=read)
        return _rows(history.text), _rows(fleet.text)

    history, fleet = csvs()
    assert [(r["run_id"], r["passed"], r["accepted"]) for r in history[::2]] == [
        (good, "True", "True"),
        (failed, "False", "True"),
    ]
    assert {r["run_id"] for r in fleet} == {failed}
    assert float(next(r for r in fleet if r["frame"] == "lidar_rear")["tx"]) == -0.43
    rejected = api.client.post(f"/v1/runs/{failed}/reject", json={"reason": "y"}, headers=override)
    assert rejected.status_code == 200, rejected.text
    history, fleet = csvs()
    assert [r["accepted"] for r in history] == ["True", "True", "False", "False"]
    assert {r["run_id"] for r in fleet} == {good}


def test_a_history_longer_than_a_page_is_all_there_once(
    api: Api, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The CSV reads the history in pages of `_PAGE` rows; 3 makes 5 runs x 2 LiDARs four pages.
    monkeypatch.setattr(csv_exports, "_PAGE", 3)
    runs = [finished(api, determined(rear_x=-0.41 - i / 1000)) for i in range(5)]
    response = api.client.get("/v1/robots/R1/history.csv", headers=api.headers("read"))
    rows = _rows(response.text)
    assert [(r["run_id"], r["frame"]) for r in rows] == [
        (run, frame) for run in runs for frame in ("lidar_front", "lidar_rear")
    ]
    assert [float(r["tx"]) for r in rows[1::2]] == [-0.41 - i / 1000 for i in range(5)]
