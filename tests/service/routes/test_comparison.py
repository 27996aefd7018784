"""Comparing two runs of a robot, on both databases: per LiDAR the change in translation and
rotation against an independent computation, both verdicts, and every bad input as a problem."""

from __future__ import annotations

import uuid

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.service.conftest import Api, problem_type
from tests.service.documents import result_document
from tests.service.routes.accepted import determined, finished


def test_compare_two_runs_per_lidar(api: Api) -> None:
    first = finished(api, determined())
    turned = determined(passed=False, rear_x=-0.44)
    yaw_5deg = Rotation.from_euler("z", 5, degrees=True) * Rotation.from_quat(
        turned["lidars"]["lidar_rear"]["calibrated"]["rotation_xyzw"]
    )
    turned["lidars"]["lidar_rear"]["calibrated"]["rotation_xyzw"] = [
        float(v) for v in yaw_5deg.as_quat()
    ]
    second = finished(api, turned)
    response = api.client.get(
        f"/v1/robots/R1/compare?from={first}&to={second}", headers=api.headers("read")
    )
    assert response.status_code == 200, response.text
    body = response.json()
    assert body["from_run"]["run_id"] == first and body["from_run"]["passed"] is True
    assert body["to_run"]["run_id"] == second and body["to_run"]["passed"] is False
    rear = body["lidars"]["lidar_rear"]
    assert rear["translation_m"] == pytest.approx(0.03, abs=1e-9)
    assert rear["delta_translation"] == pytest.approx([-0.03, 0.0, 0.0], abs=1e-9)
    assert rear["rotation_deg"] == pytest.approx(5.0, abs=1e-6)
    front = body["lidars"]["lidar_front"]
    assert front["translation_m"] == 0 and front["rotation_deg"] == pytest.approx(0, abs=1e-6)
    assert np.isclose(rear["translation_m"], np.linalg.norm(rear["delta_translation"]))


def test_a_lidar_one_run_did_not_determine_is_shown_as_such(api: Api) -> None:
    first = finished(api, determined())
    second = finished(api, result_document(passed=False))  # lidar_left undetermined
    body = api.client.get(
        f"/v1/robots/R1/compare?from={first}&to={second}", headers=api.headers("read")
    ).json()
    assert body["lidars"]["lidar_left"] == {
        "translation_m": None,
        "rotation_deg": None,
        "delta_translation": None,
        "in_from": False,
        "in_to": False,
    }


def test_compare_refuses_runs_of_another_robot_or_without_result(api: Api) -> None:
    mine = finished(api, determined())
    theirs = finished(api, determined(), robot="R2")
    queued = api.upload().json()["id"]
    cases = [
        (f"from={mine}&to={theirs}", 404, "run-not-found"),
        (f"from={mine}&to={uuid.uuid4()}", 404, "run-not-found"),
        (f"from={mine}&to={queued}", 409, "run-has-no-result"),
        (f"from={mine}", 422, "invalid-request"),
        (f"from={mine}&to=nope", 422, "invalid-request"),
    ]
    for query, status, slug in cases:
        response = api.client.get(f"/v1/robots/R1/compare?{query}", headers=api.headers("read"))
        assert (response.status_code, problem_type(response)) == (status, slug), query


def test_compare_needs_a_key_that_reads_the_robot(api: Api) -> None:
    runs = [finished(api, determined(), robot="R2") for _ in range(2)]
    query = f"from={runs[0]}&to={runs[1]}"
    response = api.client.get(f"/v1/robots/R2/compare?{query}", headers=api.headers("upload_r1"))
    assert response.status_code == 403 and problem_type(response) == "forbidden"


def test_both_sides_say_whether_an_operator_overrode_the_verdict(api: Api) -> None:
    first = finished(api, determined())
    second = finished(api, determined(passed=False, rear_x=-0.43))
    override = api.headers("override")
    api.client.post(f"/v1/runs/{first}/reject", json={"reason": "x"}, headers=override)
    api.client.post(f"/v1/runs/{second}/accept", json={"reason": "y"}, headers=override)
    body = api.client.get(
        f"/v1/robots/R1/compare?from={first}&to={second}", headers=api.headers("read")
    ).json()
    assert (body["from_run"]["passed"], body["from_run"]["accepted"]) == (True, False)
    assert (body["to_run"]["passed"], body["to_run"]["accepted"]) == (False, True)
    assert body["lidars"]["lidar_rear"]["translation_m"] == pytest.approx(0.02, abs=1e-9)
