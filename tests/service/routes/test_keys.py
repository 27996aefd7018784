"""`GET /v1/keys/me`, on both databases: each key sees its own id, name, scopes and robot, never
its secret; without a valid key it is a 401 like every other endpoint."""

from __future__ import annotations

import pytest

from tests.service.conftest import Api, problem_type


@pytest.mark.parametrize(
    ("key", "scopes", "name", "robot"),
    [
        ("admin", ["admin"], None, None),
        ("read", ["read"], None, None),
        ("override", ["override"], "line-lead", None),
        ("upload_r1", ["upload"], None, "R1"),
    ],
)
def test_a_key_sees_what_it_may_do(
    api: Api, key: str, scopes: list[str], name: str | None, robot: str | None
) -> None:
    response = api.client.get("/v1/keys/me", headers=api.headers(key))
    assert response.status_code == 200, response.text
    body = response.json()
    assert body == {
        "id": api.keys[key].split("_")[1],
        "name": name,
        "scopes": scopes,
        "robot_id": robot,
    }
    assert api.keys[key] not in response.text


@pytest.mark.parametrize("key", [None, "revoked"])
def test_no_or_a_revoked_key_is_401(api: Api, key: str | None) -> None:
    response = api.client.get("/v1/keys/me", headers=api.headers(key) if key else {})
    assert response.status_code == 401 and problem_type(response) == "unauthenticated"
