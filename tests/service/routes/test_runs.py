"""Uploads, runs and the runs listing: the happy path, every bad input (its status and problem
type, with nothing stored), idempotency, and cursor pagination that stays stable under inserts."""

from __future__ import annotations

import hashlib
import json
import threading
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest

from pipeline.result_model import ResultDocument
from service import repository
from service.models import Run, RunStatus
from service.settings import Settings
from tests.service.conftest import MCAP_MAGIC, Api, problem_type, recording, running_api
from tests.service.documents import result_document
from tests.service.uploads import new_upload


def test_upload_stores_the_recording_and_queues_a_run(api: Api) -> None:
    body = recording(100_000)
    config = {"frames": {"reference_frame": "lidar_front"}}
    response = api.upload(
        "R1",
        body,
        kind="maintenance",
        **{
            "X-Content-SHA256": hashlib.sha256(body).hexdigest().upper(),
            "X-Fleetcal-Config": json.dumps(config),
        },
    )
    assert response.status_code == 202, response.text
    run = response.json()
    assert response.headers["location"] == f"/v1/runs/{run['id']}"
    assert run["status"] == "queued" and run["kind"] == "maintenance"
    assert run["robot_id"] == "R1" and run["attempts"] == 0 and run["max_attempts"] == 3
    assert run["upload"] == {
        "size": len(body),
        "sha256": hashlib.sha256(body).hexdigest(),
        "format": "mcap",
    }
    assert run["config"] == config and run["result"] is None and run["error"] is None

    with api.services.db.session() as session:
        row = session.get(Run, uuid.UUID(run["id"]))
        assert row is not None and row.status == RunStatus.QUEUED
        assert repository.get_robot(session, "R1") is not None  # created on first upload
    with api.storage.open(row.storage_key) as stored:
        assert stored.read() == body
    assert api.storage.temporary_uploads() == []

    fetched = api.client.get(response.headers["location"], headers=api.headers("read"))
    assert fetched.status_code == 200 and fetched.json() == run


@pytest.mark.parametrize(
    ("head", "fmt"),
    [
        (b"#ROSBAG V2.0\n", "ros1"),
        (b"SQLite format 3\x00", "sqlite3"),
        (b"PK\x03\x04", "zip"),
        (b"\x1f\x8b\x08\x00", "tar.gz"),
        (b"\x00" * 257 + b"ustar\x0000", "tar"),
    ],
)
def test_every_recording_format_is_recognised(api: Api, head: bytes, fmt: str) -> None:
    response = api.upload("R1", head + b"\x00" * 600)
    assert response.status_code == 202, response.text
    assert response.json()["upload"]["format"] == fmt


def test_a_tiny_recording_is_checked_on_what_arrived(api: Api) -> None:
    response = api.upload("R1", MCAP_MAGIC)
    assert response.status_code == 202 and response.json()["upload"]["size"] == len(MCAP_MAGIC)


# -- bad input: its status and problem type, and nothing stored -----------------------------------


def _assert_nothing_stored(api: Api) -> None:
    assert api.run_count() == 0
    assert api.stored_files() == []


# Configs an outside probe sent (issue 15): the first three were 500s (RecursionError; NaN and
# Infinity, which PostgreSQL refuses in JSON), the last two queued runs that failed in the worker.
DEEP_CONFIG = '{"frames": ' + "[" * 5000 + "]" * 5000 + "}"
NAN_CONFIG = '{"frames": {"base_height_above_floor_m": NaN}}'
INF_CONFIG = '{"frames": {"base_height_above_floor_m": Infinity}}'
INVALID_CONFIG = '{"optimisation": {"max_iterations": 0}}'
VERDICT_CONFIG = '{"verdict": {"max_metric_error_m": 100}}'


@pytest.mark.parametrize(
    ("body", "headers", "query", "status", "slug"),
    [
        (b"GIF89a" + b"\x00" * 2000, {}, "kind=end_of_line", 415, "unsupported-recording-format"),
        (b"hello", {}, "kind=end_of_line", 415, "unsupported-recording-format"),
        (b"", {}, "kind=end_of_line", 400, "empty-upload"),
        (None, {"X-Content-SHA256": "0" * 64}, "kind=end_of_line", 422, "checksum-mismatch"),
        (None, {"X-Content-SHA256": "not-a-hash"}, "kind=end_of_line", 422, "invalid-request"),
        (None, {"X-Fleetcal-Config": "{not json"}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": "[1, 2]"}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": DEEP_CONFIG}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": NAN_CONFIG}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": INF_CONFIG}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": INVALID_CONFIG}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": VERDICT_CONFIG}, "kind=end_of_line", 422, "invalid-config"),
        (None, {"X-Fleetcal-Config": "x" * 20_000}, "kind=end_of_line", 422, "invalid-request"),
        (None, {"Idempotency-Key": "a b"}, "kind=end_of_line", 422, "invalid-request"),
        (None, {}, "kind=daily", 422, "invalid-request"),
        (None, {}, "", 422, "invalid-request"),
    ],
    ids=[
        "not-a-recording",
        "tiny-text",
        "empty",
        "sha-mismatch",
        "sha-malformed",
        "config-not-json",
        "config-not-object",
        "config-nested-5000-deep",
        "config-nan",
        "config-infinity",
        "config-not-a-pipeline-config",
        "config-sets-its-verdict",
        "config-huge",
        "idempotency-key-space",
        "unknown-kind",
        "no-kind",
    ],
)
def test_bad_uploads_are_refused_with_nothing_stored(
    api: Api, body: bytes | None, headers: dict[str, str], query: str, status: int, slug: str
) -> None:
    content = recording() if body is None else body
    response = api.client.post(
        f"/v1/robots/R1/runs?{query}", content=content, headers=api.headers("admin", **headers)
    )
    assert response.status_code == status, response.text
    assert problem_type(response) == slug
    _assert_nothing_stored(api)


def test_a_bad_robot_id_is_refused(api: Api) -> None:
    response = api.upload("..", recording())  # the client resolves it to POST /v1/runs
    assert response.status_code == 405 and problem_type(response) == "method-not-allowed"
    response = api.upload("R1%2F..%2Fetc", recording())  # decoded to slashes: no such route
    assert response.status_code == 404 and problem_type(response) == "not-found"
    response = api.upload("-R1", recording())
    assert response.status_code == 422 and problem_type(response) == "invalid-request"
    _assert_nothing_stored(api)


def test_an_upload_over_the_limit_is_refused_as_declared(api: Api) -> None:
    limit = api.services.settings.max_upload_bytes
    response = api.client.post(
        "/v1/robots/R1/runs?kind=end_of_line",
        headers=api.headers("admin", **{"Content-Length": str(limit + 1)}),
        content=recording(limit + 1),
    )
    assert response.status_code == 413 and problem_type(response) == "upload-too-large"
    assert response.json()["limit"] == limit
    _assert_nothing_stored(api)


def test_an_upload_over_the_limit_is_refused_while_streaming(api: Api) -> None:
    limit = api.services.settings.max_upload_bytes
    chunk = recording(1024 * 1024)

    def chunks() -> Iterator[bytes]:  # chunked transfer: no Content-Length to check up front
        for _ in range(limit // len(chunk) + 2):
            yield chunk

    response = api.client.post(
        "/v1/robots/R1/runs?kind=end_of_line", content=chunks(), headers=api.headers("admin")
    )
    assert response.status_code == 413 and problem_type(response) == "upload-too-large"
    _assert_nothing_stored(api)


def test_unknown_robots_are_refused_when_creation_is_off(settings: Settings) -> None:
    with running_api(settings.model_copy(update={"create_robots_on_upload": False})) as api:
        response = api.upload("ghost", recording())
        assert response.status_code == 404 and problem_type(response) == "robot-not-found"
        _assert_nothing_stored(api)
        registered = api.client.put("/v1/robots/ghost", json={}, headers=api.headers("admin"))
        assert registered.status_code == 201
        assert api.upload("ghost", recording()).status_code == 202


# -- idempotency ----------------------------------------------------------------------------------


def test_a_repeated_idempotency_key_returns_the_first_run(api: Api) -> None:
    body = recording(50_000)
    first = api.upload("R1", body, **{"Idempotency-Key": "eol-2026-0001"})
    again = api.upload(
        "R1",
        body,
        **{
            "Idempotency-Key": "eol-2026-0001",
            "X-Content-SHA256": hashlib.sha256(body).hexdigest(),
        },
    )
    assert first.status_code == again.status_code == 202
    assert again.json()["id"] == first.json()["id"]
    assert again.headers["idempotent-replayed"] == "true"
    assert again.headers["location"] == first.headers["location"]
    assert api.run_count() == 1
    assert len(api.stored_files()) == 1

    other_robot = api.upload("R2", body, **{"Idempotency-Key": "eol-2026-0001"})
    assert other_robot.json()["id"] != first.json()["id"]
    assert api.run_count() == 2


def test_concurrent_uploads_with_one_idempotency_key_make_one_run(api: Api) -> None:
    # The first upload's transaction is still open when the second checks the key and streams;
    # the second's insert then waits for it, collides with it, and answers with its run.
    first_id = uuid.uuid4()
    first = api.services.db.write_session()
    first.begin()
    repository.record_upload(
        first,
        new_upload(run_id=first_id, size=4096, idempotency_key="race"),
        create_robot=True,
    )
    answers: list[Any] = []
    second = threading.Thread(
        target=lambda: answers.append(api.upload("R1", recording(), **{"Idempotency-Key": "race"}))
    )
    second.start()
    second.join(1.0)
    first.commit()
    first.close()
    second.join(60)
    assert answers and answers[0].status_code == 202, answers
    assert answers[0].json()["id"] == str(first_id)
    assert api.run_count() == 1
    assert api.stored_files() == []  # the second body was stored, then removed


def test_an_idempotency_key_reused_for_another_body_or_kind_is_refused(api: Api) -> None:
    first = api.upload("R1", recording(seed=1), **{"Idempotency-Key": "k"})
    assert first.status_code == 202
    other = recording(seed=2)
    response = api.upload(
        "R1",
        other,
        **{"Idempotency-Key": "k", "X-Content-SHA256": hashlib.sha256(other).hexdigest()},
    )
    assert response.status_code == 422 and problem_type(response) == "idempotency-key-reused"
    assert response.json()["run_id"] == first.json()["id"]
    response = api.upload("R1", recording(seed=1), kind="maintenance", **{"Idempotency-Key": "k"})
    assert response.status_code == 422 and problem_type(response) == "idempotency-key-reused"
    assert api.run_count() == 1 and len(api.stored_files()) == 1


# -- reading runs ---------------------------------------------------------------------------------


def test_get_run_shows_the_result_once_stored(api: Api) -> None:
    run_id = api.upload("R1").json()["id"]
    document = result_document()
    with api.services.db.transaction() as session:
        repository.store_result(session, uuid.UUID(run_id), document)
    run = api.client.get(f"/v1/runs/{run_id}", headers=api.headers("read")).json()
    assert run["status"] == "succeeded" and run["passed"] is True
    assert run["metric_error_final"] == 0.0012
    # The result model of the stored document: its data, defaults filled in, angles derived.
    assert run["result"] == ResultDocument.model_validate(document).model_dump(mode="json")
    assert run["result"]["lidars"]["lidar_left"]["initial"]["rpy_deg"] == pytest.approx(
        [0.0, 0.0, 90.0]
    )
    assert run["finished_at"] is not None and run["progress"] == 1.0


def test_get_run_shows_the_problem_of_a_failed_run(api: Api) -> None:
    from service.problem_details import problem_document

    run_id = api.upload("R1").json()["id"]
    problem = problem_document(
        "corrupt-recording", "Corrupt recording", 422, "the MCAP summary is truncated at byte 4096"
    )
    with api.services.db.transaction() as session:
        repository.fail_run(session, uuid.UUID(run_id), problem)
    run = api.client.get(f"/v1/runs/{run_id}", headers=api.headers("read")).json()
    assert run["status"] == "failed" and run["error"] == problem and run["result"] is None


def test_get_run_problems(api: Api) -> None:
    response = api.client.get(f"/v1/runs/{uuid.uuid4()}", headers=api.headers("read"))
    assert response.status_code == 404 and problem_type(response) == "run-not-found"
    response = api.client.get("/v1/runs/not-a-uuid", headers=api.headers("read"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"


def test_a_robot_key_reads_its_own_runs_only(api: Api) -> None:
    own = api.upload("R1", key="upload_r1")
    assert own.status_code == 202
    other = api.upload("R2", key="admin").json()["id"]
    assert (
        api.client.get(own.headers["location"], headers=api.headers("upload_r1")).status_code == 200
    )
    response = api.client.get(f"/v1/runs/{other}", headers=api.headers("upload_r1"))
    assert response.status_code == 403 and problem_type(response) == "forbidden"


# -- listing runs ---------------------------------------------------------------------------------


def _ids(page: dict) -> list[str]:  # type: ignore[type-arg]
    return [item["id"] for item in page["items"]]


def test_list_runs_filters(api: Api) -> None:
    eol = api.upload("R1", kind="end_of_line").json()["id"]
    kept = api.upload("R1", kind="maintenance").json()["id"]
    failed = api.upload("R1", kind="maintenance").json()["id"]
    other = api.upload("R2", kind="maintenance").json()["id"]
    with api.services.db.transaction() as session:
        repository.store_result(session, uuid.UUID(kept), result_document(passed=True))
        repository.store_result(session, uuid.UUID(eol), result_document(passed=False))
    with api.services.db.transaction() as session:
        repository.fail_run(
            session, uuid.UUID(failed), {"type": "x", "title": "t", "status": 422, "detail": "d"}
        )

    def listing(query: str) -> list[str]:
        response = api.client.get(f"/v1/runs?{query}", headers=api.headers("read"))
        assert response.status_code == 200, response.text
        return _ids(response.json())

    assert listing("") == [other, failed, kept, eol]  # newest first
    assert listing("robot_id=R1") == [failed, kept, eol]
    assert listing("robot_id=R2&kind=maintenance") == [other]
    assert listing("kind=end_of_line") == [eol]
    assert listing("status=failed") == [failed]
    assert listing("status=queued") == [other]
    assert listing("passed=true") == [kept]
    assert listing("passed=false") == [eol]
    assert listing("status=succeeded&robot_id=R1") == [kept, eol]
    future = (datetime.now(UTC) + timedelta(hours=1)).isoformat()
    assert listing(f"since={future.replace('+', '%2B')}") == []
    assert listing(f"until={future.replace('+', '%2B')}") == [other, failed, kept, eol]
    items = api.client.get("/v1/runs?robot_id=R1", headers=api.headers("read")).json()["items"]
    assert {item["id"]: item["passed"] for item in items} == {failed: None, kept: True, eol: False}


def test_pagination_is_stable_under_inserts(api: Api) -> None:
    original = [api.upload("R1").json()["id"] for _ in range(7)][::-1]  # newest first
    first = api.client.get("/v1/runs?limit=3", headers=api.headers("read")).json()
    assert _ids(first) == original[:3] and first["next_cursor"]

    inserted = [api.upload("R1").json()["id"] for _ in range(2)]  # newer than every page

    seen, cursor = _ids(first), first["next_cursor"]
    while cursor:
        page = api.client.get(f"/v1/runs?limit=3&cursor={cursor}", headers=api.headers("read"))
        assert page.status_code == 200
        seen += _ids(page.json())
        cursor = page.json()["next_cursor"]
    assert seen == original  # no repeat, no gap, none of the new runs mid-way
    fresh = api.client.get("/v1/runs?limit=3", headers=api.headers("read")).json()
    assert _ids(fresh)[:2] == inserted[::-1]


def test_the_last_page_has_no_cursor(api: Api) -> None:
    for _ in range(2):
        api.upload("R1")
    page = api.client.get("/v1/runs?limit=2", headers=api.headers("read")).json()
    assert len(page["items"]) == 2 and page["next_cursor"] is None


@pytest.mark.parametrize(
    "cursor",
    [
        "garbage!",
        "bm90IGpzb24",
        "WyJydW5zIiwiMjAyNi0wMS0wMVQwMDowMDowMCswMDowMCJd",
        "WyJydW5zIiwibm90LWEtZGF0ZSIsIjEyMyJd",
        "WyJyb2JvdHMiLCJSMSJd",
    ],
    ids=["not-base64", "not-json", "short", "damaged", "other-listing"],
)
def test_an_invalid_cursor_is_a_400_problem(api: Api, cursor: str) -> None:
    response = api.client.get(f"/v1/runs?cursor={cursor}", headers=api.headers("read"))
    assert response.status_code == 400 and problem_type(response) == "invalid-cursor"


@pytest.mark.parametrize(
    "query",
    [
        "limit=0",
        "limit=501",
        "status=lost",
        "passed=maybe",
        "since=yesterday",
        "since=2026-01-01T00:00:00",
        "robot_id=a/b",
    ],
)
def test_bad_listing_parameters_are_422_problems(api: Api, query: str) -> None:
    response = api.client.get(f"/v1/runs?{query}", headers=api.headers("read"))
    assert response.status_code == 422 and problem_type(response) == "invalid-request"
    assert response.json()["errors"]
