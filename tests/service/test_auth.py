"""API keys: stored hashed, checked in full, revocable; and every endpoint's authorisation matrix
(no key 401, revoked key 401, wrong scope or robot 403, the right key through)."""

from __future__ import annotations

import uuid

import pytest
from sqlalchemy import select

from service.auth import authenticate, create_key, hash_key, list_keys, revoke_key
from service.db import Database
from service.models import ApiKey, Scope
from tests.service.conftest import Api, problem_type, recording


def test_keys_are_stored_hashed_and_authenticate_in_full(api: Api) -> None:
    db: Database = api.services.db
    with db.transaction() as session:
        key = create_key(session, [Scope.UPLOAD], robot_id="R7", name="station 3")
    with db.session() as session:
        row = session.get(ApiKey, key.id)
        assert row is not None and row.key_hash == hash_key(key.secret)
        assert key.secret not in repr(row.__dict__)
        principal = authenticate(session, key.secret)
        assert principal is not None and principal.robot_id == "R7"
        assert principal.scopes == {Scope.UPLOAD} and principal.key_id == key.id
        # Same id, another secret; a truncated key; junk: all rejected alike.
        forged = key.secret[:-4] + ("AAAA" if not key.secret.endswith("AAAA") else "BBBB")
        assert authenticate(session, forged) is None
        assert authenticate(session, key.secret[:-1]) is None
        assert authenticate(session, "fck_000000000000_" + "A" * 43) is None
        assert authenticate(session, "") is None


def test_revoked_keys_stop_working(api: Api) -> None:
    db = api.services.db
    with db.transaction() as session:
        key = create_key(session, [Scope.READ])
    with db.transaction() as session:
        assert revoke_key(session, key.id) is True
        assert revoke_key(session, "nosuchkey") is False
    with db.session() as session:
        assert authenticate(session, key.secret) is None
        revoked = [k for k in list_keys(session) if k.id == key.id]
        assert revoked[0].revoked_at is not None
    response = api.client.get("/v1/runs", headers={"X-API-Key": key.secret})
    assert response.status_code == 401


def test_only_upload_keys_bind_to_a_robot(api: Api) -> None:
    with api.services.db.transaction() as session, pytest.raises(ValueError, match="upload"):
        create_key(session, [Scope.READ], robot_id="R1")
    with api.services.db.transaction() as session, pytest.raises(ValueError, match="scope"):
        create_key(session, [])


def test_bearer_and_header_keys_both_work(api: Api) -> None:
    key = api.keys["read"]
    assert api.client.get("/v1/runs", headers={"Authorization": f"Bearer {key}"}).status_code == 200
    assert api.client.get("/v1/runs", headers={"X-API-Key": key}).status_code == 200
    response = api.client.get("/v1/runs", headers={"Authorization": f"Basic {key}"})
    assert response.status_code == 401 and response.headers["www-authenticate"].startswith("Bearer")


# -- the matrix -----------------------------------------------------------------------------------

RUN = str(uuid.UUID(int=1))
# (method, path, body) of every /v1 endpoint, and the keys that must get through (not 401/403).
ENDPOINTS: list[tuple[str, str, object, set[str]]] = [
    ("POST", "/v1/robots/R1/runs?kind=end_of_line", "recording", {"admin", "upload", "upload_r1"}),
    ("POST", "/v1/robots/R2/runs?kind=end_of_line", "recording", {"admin", "upload"}),
    ("GET", f"/v1/runs/{RUN}", None, {"admin", "read", "upload", "upload_r1"}),
    ("GET", "/v1/runs", None, {"admin", "read"}),
    ("GET", "/v1/robots", None, {"admin", "read"}),
    ("GET", "/v1/robots/R1", None, {"admin", "read", "upload", "upload_r1"}),
    ("GET", "/v1/robots/R2", None, {"admin", "read", "upload"}),
    ("PUT", "/v1/robots/R1", {"model": "mk2"}, {"admin"}),
    ("GET", "/v1/robots/R1/calibration", None, {"admin", "read", "upload", "upload_r1"}),
    ("GET", "/v1/robots/R2/calibration", None, {"admin", "read", "upload"}),
    ("GET", "/v1/robots/R1/history", None, {"admin", "read", "upload", "upload_r1"}),
    ("GET", "/v1/robots/R2/history", None, {"admin", "read", "upload"}),
    ("GET", "/v1/tolerance-profiles", None, {"admin", "read"}),
    ("GET", "/v1/tolerance-profiles/default", None, {"admin", "read"}),
    ("PUT", "/v1/tolerance-profiles/default", {"is_default": True}, {"admin"}),
]
KEYS = ["admin", "read", "upload", "upload_r1", "revoked", "none", "junk"]


def _call(api: Api, method: str, path: str, body: object, key: str):  # type: ignore[no-untyped-def]
    special = {"none": {}, "junk": {"X-API-Key": "fck_0_0"}}
    headers = special[key] if key in special else api.headers(key)
    if body == "recording":
        return api.client.request(method, path, content=recording(), headers=headers)
    return api.client.request(method, path, json=body, headers=headers)


@pytest.mark.parametrize(
    ("method", "path", "body", "allowed"), ENDPOINTS, ids=[f"{m} {p}" for m, p, _, _ in ENDPOINTS]
)
def test_authorisation_matrix(
    api: Api, method: str, path: str, body: object, allowed: set[str]
) -> None:
    for key in KEYS:
        response = _call(api, method, path, body, key)
        if key in ("revoked", "none", "junk"):
            expected = 401
        elif key in allowed:
            assert response.status_code not in (401, 403), (key, response.text)
            continue
        else:
            expected = 403
        assert response.status_code == expected, (key, response.text)
        assert problem_type(response) == ("unauthenticated" if expected == 401 else "forbidden")


def test_refused_requests_store_nothing(api: Api) -> None:
    for key in ("read", "upload_r1", "revoked", "none"):
        response = _call(api, "POST", "/v1/robots/R2/runs?kind=end_of_line", "recording", key)
        assert response.status_code in (401, 403)
    assert api.run_count() == 0 and api.stored_files() == []


@pytest.mark.parametrize("path", ["/healthz", "/readyz", "/metrics"])
def test_probes_need_no_key(api: Api, path: str) -> None:
    assert api.client.get(path).status_code == 200


def test_keys_never_appear_in_responses_or_the_database(api: Api) -> None:
    listing = api.client.get("/v1/runs", headers=api.headers("admin")).text
    assert all(secret not in listing for secret in api.keys.values())
    with api.services.db.session() as session:
        hashes = set(session.scalars(select(ApiKey.key_hash)))
    assert not hashes & set(api.keys.values())
