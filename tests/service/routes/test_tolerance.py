"""Tolerance profiles: admin writes (created, replaced, one default, one per model), reads."""

from __future__ import annotations

import pytest

from service import repository
from tests.service.conftest import Api, problem_type

POSE = {"translation": [0.45, 0.0, 0.62], "rotation_xyzw": [0, 0, 0, 1]}
STRICT = {
    "robot_model": "mk2",
    "limits": {
        "max_metric_error_m": 0.003,
        "max_translation_drift_m": 0.01,
        "max_rotation_drift_deg": 0.5,
    },
    "design_extrinsics": {
        "lidar_front": {"translation": [0.45, 0.0, 0.62], "rotation_xyzw": [0, 0, 0, 1]},
    },
}


def test_put_creates_then_replaces(api: Api) -> None:
    created = api.client.put(
        "/v1/tolerance-profiles/mk2", json=STRICT, headers=api.headers("admin")
    )
    assert created.status_code == 201, created.text
    body = created.json()
    assert body["name"] == "mk2" and body["robot_model"] == "mk2" and not body["is_default"]
    assert body["limits"]["max_metric_error_m"] == 0.003
    assert body["limits"]["max_translation_stddev_m"] is None
    assert body["design_extrinsics"]["lidar_front"]["translation"] == [0.45, 0.0, 0.62]

    replaced = api.client.put(
        "/v1/tolerance-profiles/mk2", json={"robot_model": "mk2"}, headers=api.headers("admin")
    )
    assert replaced.status_code == 200
    assert replaced.json()["limits"]["max_metric_error_m"] is None
    assert replaced.json()["design_extrinsics"] is None
    fetched = api.client.get("/v1/tolerance-profiles/mk2", headers=api.headers("read"))
    assert fetched.status_code == 200 and fetched.json() == replaced.json()


def test_one_default_and_one_profile_per_model(api: Api) -> None:
    admin = api.headers("admin")
    api.client.put("/v1/tolerance-profiles/a", json={"is_default": True}, headers=admin)
    api.client.put("/v1/tolerance-profiles/b", json={"is_default": True}, headers=admin)
    listing = api.client.get("/v1/tolerance-profiles", headers=api.headers("read")).json()
    assert [(p["name"], p["is_default"]) for p in listing["items"]] == [("a", False), ("b", True)]

    api.client.put("/v1/tolerance-profiles/mk2", json=STRICT, headers=admin)
    clash = api.client.put(
        "/v1/tolerance-profiles/other", json={"robot_model": "mk2"}, headers=admin
    )
    assert clash.status_code == 409 and problem_type(clash) == "conflict"
    assert api.client.get("/v1/tolerance-profiles/other", headers=admin).status_code == 404


@pytest.mark.parametrize(
    "body",
    [
        {"limits": {"max_metric_error_m": -1}},
        {"limits": {"max_metric_error_m": 0}},
        {"limits": {"unknown_limit": 1}},
        {
            "design_extrinsics": {
                "lidar_front": {"translation": [0, 0], "rotation_xyzw": [0, 0, 0, 1]}
            }
        },
        {"robot_model": "has space"},
        {"is_default": "perhaps"},
        # Booleans must be JSON booleans: 0 and "true" passed as bools.
        {"is_default": 0},
        {"is_default": 1},
        {"is_default": "true"},
        # A pose the worker cannot use failed every end-of-line run of the model in `drift`.
        {"design_extrinsics": {"lidar_front": {**POSE, "rotation_xyzw": [0, 0, 0, 0]}}},
        {"design_extrinsics": {"lidar_front": {**POSE, "rotation_xyzw": [1e-12, 0, 0, 0]}}},
        {"design_extrinsics": {"lidar_front": {**POSE, "rotation_xyzw": [1e308, 1e308, 0, 0]}}},
        {"design_extrinsics": {"lidar\x00front": POSE}},
        # Numbers must be JSON numbers (the API fuzzer's find: `true` was stored as 1 m).
        {"limits": {"max_translation_drift_m": True}},
        {"limits": {"max_rotation_drift_deg": "0.5"}},
        {
            "design_extrinsics": {
                "lidar_front": {"translation": [0, 0, "1"], "rotation_xyzw": [0, 0, 0, 1]}
            }
        },
    ],
)
def test_bad_profiles_are_refused(api: Api, body: dict[str, object]) -> None:
    response = api.client.put("/v1/tolerance-profiles/p", json=body, headers=api.headers("admin"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"
    assert api.client.get("/v1/tolerance-profiles", headers=api.headers("read")).json() == {
        "items": []
    }


def test_non_finite_limits_are_refused(api: Api) -> None:
    response = api.client.put(
        "/v1/tolerance-profiles/p",
        headers=api.headers("admin", **{"Content-Type": "application/json"}),
        content=b'{"limits": {"max_metric_error_m": NaN}}',
    )
    assert response.status_code == 422 and problem_type(response) == "invalid-request"


def test_unknown_profile_and_bad_name(api: Api) -> None:
    response = api.client.get("/v1/tolerance-profiles/nope", headers=api.headers("read"))
    assert response.status_code == 404 and problem_type(response) == "tolerance-profile-not-found"
    response = api.client.put("/v1/tolerance-profiles/-x", json={}, headers=api.headers("admin"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"


def test_a_quaternion_off_unit_length_is_accepted_as_the_worker_normalises_it(api: Api) -> None:
    body = {"design_extrinsics": {"lidar_front": {**POSE, "rotation_xyzw": [0, 0, 0, 2]}}}
    response = api.client.put("/v1/tolerance-profiles/p", json=body, headers=api.headers("admin"))
    assert response.status_code == 201, response.text
    assert response.json()["design_extrinsics"]["lidar_front"]["rotation_xyzw"] == [0, 0, 0, 2]


def test_a_profile_stored_before_poses_were_checked_still_shows(api: Api) -> None:
    """So that an admin can see it and replace it."""
    broken = {"lidar_front": {**POSE, "rotation_xyzw": [0.0, 0.0, 0.0, 0.0]}}
    with api.services.db.transaction() as session:
        repository.put_tolerance_profile(
            session, "old", robot_model=None, is_default=False, limits={}, design_extrinsics=broken
        )
    response = api.client.get("/v1/tolerance-profiles/old", headers=api.headers("read"))
    assert response.status_code == 200, response.text
    assert response.json()["design_extrinsics"] == broken
