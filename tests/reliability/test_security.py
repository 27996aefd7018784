"""Security on SQLite and PostgreSQL: every endpoint's authorisation matrix (the one in
tests/service/test_auth.py plus the endpoints it leaves out, on real runs of two robots), keys
never logged nor returned, uploads that cannot write outside storage, and SQL that only ever
carries values as bound parameters (a source check, and injection strings in every parameter)."""

from __future__ import annotations

import ast
import hashlib
import logging
import re
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import func, select

from service import repository
from service.models import ApiKey, Robot, Run
from tests.service.conftest import Api, problem_type, recording
from tests.service.documents import result_document
from tests.service.test_auth import ENDPOINTS as SERVICE_MATRIX
from tests.service.test_auth import KEYS, _call

ROOT = Path(__file__).resolve().parents[2]
EVERYONE = {"admin", "read", "upload", "upload_r1"}
NOT_R1 = {"admin", "read", "upload"}  # the key bound to R1 may not touch R2's runs
PUBLIC = ["/healthz", "/readyz", "/metrics", "/", "/dashboard/dashboard.js", "/openapi.json"]


@pytest.fixture
def runs(api: Api) -> dict[str, str]:
    """A finished run of R1 and one of R2 (so that reports and exports get past the lookup)."""
    ids = {}
    for robot in ("R1", "R2"):
        response = api.upload(robot, recording())
        assert response.status_code == 202, response.text
        ids[robot] = response.json()["id"]
        with api.services.db.transaction() as session:
            repository.store_result(session, uuid.UUID(ids[robot]), result_document())
    return ids


def extra_matrix(runs: dict[str, str]) -> list[tuple[str, str, object, set[str]]]:
    """The endpoints the service tests' matrix leaves out, and runs that exist."""
    rows: list[tuple[str, str, object, set[str]]] = [
        ("GET", "/v1/fleet", None, {"admin", "read"}),
        ("GET", "/v1/keys/me", None, EVERYONE),  # any valid key may ask what it may do
    ]
    for robot, allowed in (("R1", EVERYONE), ("R2", NOT_R1)):
        run = runs[robot]
        rows += [
            ("GET", f"/v1/runs/{run}", None, allowed),
            ("GET", f"/v1/runs/{run}/report", None, allowed),
            ("GET", f"/v1/runs/{run}/report/map-top.png", None, allowed),
            ("GET", f"/v1/runs/{run}/exports/tf-static", None, allowed),
            ("GET", f"/v1/runs/{run}/exports/recording", None, allowed),
            ("GET", f"/v1/robots/{robot}/compare?from={run}&to={run}", None, allowed),
            ("GET", f"/v1/robots/{robot}/history.csv", None, allowed),
            # The override scope (admin implies it); no key of the matrix has it alone.
            ("POST", f"/v1/runs/{run}/reject", {"reason": "matrix"}, {"admin"}),
            ("POST", f"/v1/runs/{run}/accept", {"reason": "matrix"}, {"admin"}),
        ]
    hook = f"/v1/webhooks/{uuid.UUID(int=1)}"  # unknown: the admin's answer is a 404
    rows += [
        ("GET", "/v1/fleet/calibrations.csv", None, {"admin", "read"}),
        (
            "POST",
            "/v1/webhooks",
            {"url": "http://127.0.0.1:9/", "events": ["run.failed"]},
            {"admin"},
        ),
        ("GET", "/v1/webhooks", None, {"admin"}),
        ("GET", hook, None, {"admin"}),
        ("GET", f"{hook}/deliveries", None, {"admin"}),
        ("DELETE", hook, None, {"admin"}),
    ]
    return rows


def _template(path: str) -> re.Pattern[str]:
    return re.compile("^" + re.sub(r"\{[^}]+\}", "[^/]+", path) + "$")


def test_every_operation_is_in_an_authorisation_matrix(api: Api, runs: dict[str, str]) -> None:
    """A new endpoint fails this test until its keys are in a matrix."""
    document = api.client.get("/openapi.json").json()
    covered = [(m, p.split("?")[0]) for m, p, _, _ in SERVICE_MATRIX + extra_matrix(runs)]
    covered += [("GET", path) for path in PUBLIC]
    missing = [
        f"{method.upper()} {template}"
        for template, operations in document["paths"].items()
        for method in operations
        if not any(m == method.upper() and _template(template).match(p) for m, p in covered)
    ]
    assert missing == []


def test_authorisation_matrix_of_the_endpoints_left_out(api: Api, runs: dict[str, str]) -> None:
    for method, path, body, allowed in extra_matrix(runs):
        for key in KEYS:
            response = _call(api, method, path, body, key)
            where = (method, path, key, response.status_code, response.text[:200])
            if key in ("revoked", "none", "junk"):
                assert response.status_code == 401, where
                assert problem_type(response) == "unauthenticated"
            elif key in allowed:
                assert response.status_code not in (401, 403, 500), where
            else:
                assert response.status_code == 403, where
                assert problem_type(response) == "forbidden"


def test_public_paths_hold_no_data(api: Api, runs: dict[str, str]) -> None:
    """The probes, the dashboard's static files and the document need no key, and name no run."""
    for path in PUBLIC:
        response = api.client.get(path)
        assert response.status_code == 200, path
        assert all(run not in response.text for run in runs.values()), path


# -- secrets ------------------------------------------------------------------------------------


@pytest.fixture
def all_logs(caplog: pytest.LogCaptureFixture) -> Iterator[pytest.LogCaptureFixture]:
    """Every record of every logger, at DEBUG, including the service's and the server's."""
    with caplog.at_level(logging.DEBUG):
        yield caplog


def test_keys_are_never_logged_nor_returned(
    api: Api, runs: dict[str, str], all_logs: pytest.LogCaptureFixture
) -> None:
    with api.services.db.session() as session:
        hashes = set(session.scalars(select(ApiKey.key_hash)))
    secrets = set(api.keys.values())
    responses = []
    for method, path, body, _ in SERVICE_MATRIX + extra_matrix(runs):
        for key in KEYS:
            responses.append(_call(api, method, path, body, key))
    # Failures that log: a key in the wrong header form, a near miss of a real key, a server
    # error with its traceback (storage gone while a run's recording is exported).
    near_miss = api.keys["admin"][:-1] + ("A" if not api.keys["admin"].endswith("A") else "B")
    responses.append(api.client.get("/v1/runs", headers={"X-API-Key": near_miss}))
    responses.append(
        api.client.get("/v1/runs", headers={"Authorization": f"Basic {api.keys['read']}"})
    )
    for stored in api.storage.root.rglob("*"):
        if stored.is_file() and "recordings" in stored.parts:
            stored.unlink()
    responses.append(
        api.client.get(f"/v1/runs/{runs['R1']}/exports/recording", headers=api.headers("admin"))
    )
    assert len(all_logs.records) > 0, "the test must see the service's logs"
    logged = all_logs.text + "".join(str(r.args) + str(r.exc_info) for r in all_logs.records)
    answered = "".join(r.text + str(dict(r.headers)) for r in responses)
    for secret in secrets | {near_miss}:
        assert secret not in logged
        assert secret.split("_", 2)[2] not in logged, "not even the secret part"
        assert secret not in answered
    for digest in hashes:
        assert digest not in answered and digest not in logged


# -- storage -------------------------------------------------------------------------------------


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


ESCAPING_ROBOT_IDS = [
    ("/v1/robots/%2E%2E/runs", 422),
    ("/v1/robots/..%2F..%2Fescaped/runs", 404),
    ("/v1/robots/%2Fetc%2Fescaped/runs", 404),
    ("/v1/robots/R1%00/runs", 422),
    ("/v1/robots/R1%2500/runs", 422),
    ("/v1/robots/C:%5Cescaped/runs", 422),
    ("/v1/robots/.hidden/runs", 422),
]


def test_robot_ids_that_could_escape_storage_are_refused(api: Api, tmp_path: Path) -> None:
    before = _files(tmp_path)
    for path, status in ESCAPING_ROBOT_IDS:
        response = api.client.post(
            f"{path}?kind=end_of_line", content=recording(), headers=api.headers("admin")
        )
        assert response.status_code == status, (path, response.text)
        assert problem_type(response) in ("invalid-request", "not-found")
    assert _files(tmp_path) == before and api.run_count() == 0


ESCAPING_IDEMPOTENCY_KEYS = [
    "../../../../escaped",
    "/etc/escaped",
    "..\\..\\escaped",
    "%2e%2e%2fescaped",
    "~/escaped",
]


def test_idempotency_keys_never_name_a_file(api: Api, tmp_path: Path) -> None:
    """An idempotency key is a database value only: the upload lands at recordings/R1/<run id>."""
    for count, idempotency_key in enumerate(ESCAPING_IDEMPOTENCY_KEYS, start=1):
        before = _files(tmp_path)
        response = api.upload("R1", recording(), **{"Idempotency-Key": idempotency_key})
        assert response.status_code == 202, response.text
        run_id = response.json()["id"]
        added = _files(tmp_path) - before
        recordings = [p for p in added if p.is_relative_to(api.storage.root)]
        assert recordings == [api.storage.root / "recordings" / "R1" / run_id]
        others = [p for p in added if not p.is_relative_to(api.storage.root)]
        # Only the database may change outside storage (SQLite's file and its WAL).
        assert all(p.name.startswith("fleetcal.db") for p in others), others
        again = api.upload("R1", recording(), **{"Idempotency-Key": idempotency_key})
        assert again.json()["id"] == run_id and api.run_count() == count
    assert not list(tmp_path.rglob("*escaped*"))
    assert not list(Path("/etc").glob("escaped*"))


ESCAPING_FILE_NAMES = [
    "/dashboard/..%2F..%2Fsettings.py",
    "/dashboard/%2E%2E%2F__init__.py",
    "/v1/runs/{run}/report/..%2F..%2Fmetadata.png",
    "/v1/runs/{run}/report/map-top%00.png",
    "/v1/runs/{run}/exports/..%2F..%2Fetc",
]


def test_file_names_in_paths_read_nothing_outside(api: Api, runs: dict[str, str]) -> None:
    for path in ESCAPING_FILE_NAMES:
        response = api.client.get(path.format(run=runs["R1"]), headers=api.headers("admin"))
        assert 400 <= response.status_code < 500, (path, response.text)
        slug = problem_type(response)
        assert slug in ("invalid-request", "not-found", "report-image-not-found"), path


# -- SQL ------------------------------------------------------------------------------------------

# SQL the code builds as text, reviewed: statements that cannot take bound parameters.
REVIEWED_SQL = {
    ("service/db.py", 'f"PRAGMA busy_timeout = {int(busy_timeout_ms)}"'),  # an int
    ("service/db.py", 'f"BEGIN {mode}"'),  # checked against DEFERRED | IMMEDIATE just above
}
SQL_CALLS = {"text", "execute", "exec_driver_sql", "executescript", "executemany"}


def _built_strings(tree: ast.AST) -> Iterator[ast.expr]:
    """First arguments of SQL-running calls that are built from pieces at run time."""
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or not node.args:
            continue
        name = (
            node.func.attr
            if isinstance(node.func, ast.Attribute)
            else getattr(node.func, "id", None)
        )
        if name not in SQL_CALLS:
            continue
        arg = node.args[0]
        formatted = isinstance(arg, ast.Call) and getattr(arg.func, "attr", None) == "format"
        if isinstance(arg, ast.JoinedStr | ast.BinOp) or formatted:
            yield arg


def test_sql_text_is_never_built_from_values() -> None:
    found = set()
    for package in ("service", "workers", "migrations"):
        for source in sorted((ROOT / package).rglob("*.py")):
            text = source.read_text()
            for arg in _built_strings(ast.parse(text)):
                found.add((str(source.relative_to(ROOT)), ast.get_source_segment(text, arg)))
    assert found - REVIEWED_SQL == set(), "use bound parameters (text(':name'), {...})"
    assert found >= REVIEWED_SQL, "a reviewed statement is gone: drop it from REVIEWED_SQL"


INJECTIONS = [
    "' OR '1'='1",
    "R1' --",
    "'; DROP TABLE runs; --",
    '" OR ""="',
    "1; SELECT pg_sleep(0)",
    "R1%' OR robot_id LIKE '%",
    "\\'; DELETE FROM api_keys; --",
]


def _counts(api: Api) -> tuple[int, int, int]:
    with api.services.db.session() as session:
        return tuple(  # type: ignore[return-value]
            session.scalar(select(func.count()).select_from(model)) or 0
            for model in (Run, Robot, ApiKey)
        )


def test_injection_strings_in_every_parameter_are_only_values(
    api: Api, runs: dict[str, str]
) -> None:
    document = api.client.get("/openapi.json").json()
    before = _counts(api)
    headers = api.headers("admin")
    tried = 0
    for template, operations in document["paths"].items():
        get = operations.get("get")
        if get is None:
            continue
        path = template.replace("{run_id}", runs["R1"]).replace("{robot_id}", "R1")
        path = path.replace("{name}", "map-top").replace("{fmt}", "tf-static")
        for parameter in get.get("parameters", []):
            for value in INJECTIONS:
                if parameter["in"] == "query":
                    response = api.client.get(
                        path, params={parameter["name"]: value}, headers=headers
                    )
                elif parameter["in"] == "path":
                    target = template.replace("{" + parameter["name"] + "}", value)
                    target = target.replace("{run_id}", runs["R1"]).replace("{robot_id}", "R1")
                    target = target.replace("{name}", "map-top").replace("{fmt}", "tf-static")
                    response = api.client.get(target, headers=headers)
                else:
                    continue
                tried += 1
                assert response.status_code < 500, (template, parameter["name"], value)
                if response.status_code >= 400:
                    problem_type(response)
    assert tried > 50
    # A free-text filter and a cursor whose value is an injection: matched as values, nothing more.
    for value in INJECTIONS:
        history = api.client.get("/v1/robots/R1/history", params={"frame": value}, headers=headers)
        assert history.status_code == 200 and history.json()["items"] == []
    assert api.client.get("/v1/robots/R1/history", headers=headers).json()["items"], "has rows"
    from service.pagination import encode_cursor

    # A cursor holds only what the API writes (a robot id here): the injection never reaches SQL.
    for value in INJECTIONS:
        cursor = encode_cursor("robots", "zz" + value)
        page = api.client.get("/v1/robots", params={"cursor": cursor}, headers=headers)
        assert page.status_code == 400 and problem_type(page) == "invalid-cursor", value
    assert _counts(api) == before, "nothing was changed or dropped"


def test_key_hashes_are_sha256_of_the_whole_key(api: Api) -> None:
    """The stored form cannot be replayed as a key: it is a digest, and keys are checked in full."""
    with api.services.db.session() as session:
        stored = {
            row.id: row.key_hash for row in session.execute(select(ApiKey.id, ApiKey.key_hash))
        }
    for secret in api.keys.values():
        key_id = secret.split("_")[1]
        assert stored[key_id] == hashlib.sha256(secret.encode()).hexdigest()
        response = api.client.get("/v1/runs", headers={"X-API-Key": stored[key_id]})
        assert response.status_code == 401
