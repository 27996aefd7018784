"""The API behind the dashboard: the fleet overview, report images and exports (the text formats
and the calibrated recording round-trip to the stored result's transforms within 1e-9)."""

from __future__ import annotations

import contextlib
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event

from service import repository
from service.db import Database
from service.pagination import encode_cursor
from tests.pipeline.io.recordings import TRUE_EXTRINSICS
from tests.pipeline.test_export import PARSERS, assert_recording_has, assert_same
from tests.service.conftest import Api, problem_type
from tests.service.dashboard.seed import Fleet, metric_check, result_document
from tests.service.uploads import new_upload

TOLERANCE = 1e-9
# Reports and exports read storage, not queries: one database is enough for them; the fleet's
# queries run on both.
sqlite_only = pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)


def test_the_fleet_lists_each_robot_with_its_latest_run_and_calibration(
    api: Api, fleet: Fleet
) -> None:
    response = api.client.get("/v1/fleet", headers=api.headers("read"))
    assert response.status_code == 200, response.text
    robots = {item["id"]: item for item in response.json()["items"]}
    assert list(robots) == ["R1", "R2", "R3", "R4", "R5"]
    assert robots["R1"]["model"] == "demo-bot"
    assert robots["R1"]["latest_run"]["id"] == str(fleet.repaired)
    assert robots["R1"]["latest_run"]["passed"] is True
    assert robots["R1"]["latest_calibration"]["run_id"] == str(fleet.repaired)
    assert robots["R2"]["latest_run"]["status"] == "failed"
    assert robots["R2"]["latest_calibration"] is None
    assert robots["R3"]["latest_run"]["status"] == "running"
    # R4's newest run failed its verdict: the calibration in use stays the last accepted one.
    assert robots["R4"]["latest_run"]["id"] == str(fleet.diverged)
    assert robots["R4"]["latest_run"]["passed"] is False
    assert robots["R4"]["latest_calibration"]["run_id"] == str(fleet.r4_accepted[1])


def test_the_fleet_pages_by_robot_id(api: Api, fleet: Fleet) -> None:
    first = api.client.get("/v1/fleet?limit=2", headers=api.headers("read")).json()
    assert [item["id"] for item in first["items"]] == ["R1", "R2"]
    second = api.client.get(
        f"/v1/fleet?limit=2&cursor={first['next_cursor']}", headers=api.headers("read")
    ).json()
    assert [item["id"] for item in second["items"]] == ["R3", "R4"]
    third = api.client.get(
        f"/v1/fleet?limit=2&cursor={second['next_cursor']}", headers=api.headers("read")
    ).json()
    assert [item["id"] for item in third["items"]] == ["R5"]
    assert third["next_cursor"] is None


def test_the_fleet_needs_the_read_scope(api: Api, fleet: Fleet) -> None:
    assert api.client.get("/v1/fleet").status_code == 401
    response = api.client.get("/v1/fleet", headers=api.headers("upload_r1"))
    assert response.status_code == 403 and problem_type(response) == "forbidden"


@contextlib.contextmanager
def statements(db: Database) -> Iterator[list[str]]:
    """The SQL statements the engine sends while the block runs."""
    sent: list[str] = []

    def record(_conn: Any, _cursor: Any, statement: str, *_: Any) -> None:
        sent.append(statement)

    event.listen(db.engine, "before_cursor_execute", record)
    try:
        yield sent
    finally:
        event.remove(db.engine, "before_cursor_execute", record)


def add_robots(db: Database, count: int) -> None:
    """`count` more robots (F000, F001, ...), each with a passed run and a newer failed one."""
    document = result_document(TRUE_EXTRINSICS, metric=(0.05, 0.002), checks=[metric_check(0.002)])
    for index in range(count):
        robot = f"F{index:03d}"
        with db.transaction() as session:
            passed = repository.record_upload(session, new_upload(robot), create_robot=True)
            repository.store_result(session, passed.id, document)
            failed = repository.record_upload(session, new_upload(robot), create_robot=True)
            repository.fail_run(session, failed.id, {"title": "no stops", "status": 422})


def test_the_fleet_costs_one_statement_whatever_its_size(api: Api, fleet: Fleet) -> None:
    def fleet_statements() -> list[str]:
        with statements(api.services.db) as sent:
            response = api.client.get("/v1/fleet?limit=500", headers=api.headers("read"))
        assert response.status_code == 200, response.text
        return sent

    small = fleet_statements()
    add_robots(api.services.db, 60)
    large = fleet_statements()
    # Was 1 + 2 per robot (127 here); the key lookup is the same for both.
    assert len(large) == len(small)
    assert len([sql for sql in large if "runs" in sql]) == 1


def test_the_fleet_totals_count_every_robot_not_the_page(api: Api, fleet: Fleet) -> None:
    add_robots(api.services.db, 4)
    with api.services.db.transaction() as session:
        repository.put_robot(session, "Z-never-uploaded", model=None, metadata={})
    expected = {
        # F000-F003 and R4 failed after an accepted run; R1 passed; R2 failed (no result); R3
        # running; R5 failed its verdict, never accepted; Z never uploaded.
        "robots": 10,
        "latest_passed": 1,
        "latest_failed": 7,
        "in_progress": 1,
        "no_run": 1,
        "with_accepted": 6,
    }
    read = api.headers("read")
    first = api.client.get("/v1/fleet?limit=2", headers=read).json()
    assert [item["id"] for item in first["items"]] == ["F000", "F001"]
    assert first["totals"] == expected
    f000 = first["items"][0]
    assert f000["latest_run"]["status"] == "failed"
    assert f000["latest_calibration"]["metric_error_final"] == 0.002
    everyone = api.client.get("/v1/fleet?limit=7", headers=read).json()
    assert everyone["items"][-1]["id"] == "R3" and everyone["totals"] == expected
    last = api.client.get(f"/v1/fleet?cursor={everyone['next_cursor']}", headers=read).json()
    assert [item["id"] for item in last["items"]] == ["R4", "R5", "Z-never-uploaded"]
    assert last["items"][-1]["latest_run"] is None and last["totals"] == expected
    # Past the last robot: no items, the same totals.
    past = encode_cursor("robots", "Z-never-uploaded")
    beyond = api.client.get(f"/v1/fleet?cursor={past}", headers=read).json()
    assert beyond == {"items": [], "next_cursor": None, "totals": expected}


# -- report images --------------------------------------------------------------------------------


@sqlite_only
def test_a_run_lists_and_serves_its_report_images(
    api: Api, fleet: Fleet, seed_images: dict[str, bytes]
) -> None:
    index = api.client.get(f"/v1/runs/{fleet.repaired}/report", headers=api.headers("read"))
    assert index.status_code == 200, index.text
    images = index.json()["images"]
    assert [image["name"] for image in images] == ["map-top", "map-side", "error"]
    for image in images:
        response = api.client.get(image["url"], headers=api.headers("read"))
        assert response.status_code == 200
        assert response.headers["content-type"] == "image/png"
        assert response.content == seed_images[image["name"]]


@sqlite_only
def test_a_run_without_images_lists_none(api: Api, fleet: Fleet) -> None:
    index = api.client.get(f"/v1/runs/{fleet.failed}/report", headers=api.headers("read"))
    assert index.json()["images"] == []
    missing = api.client.get(
        f"/v1/runs/{fleet.failed}/report/map-top.png", headers=api.headers("read")
    )
    assert missing.status_code == 404
    assert problem_type(missing) == "report-image-not-found"


@sqlite_only
@pytest.mark.parametrize(
    ("path", "key", "status", "problem"),
    [
        ("/v1/runs/{run}/report/map-front.png", "read", 404, "report-image-not-found"),
        (f"/v1/runs/{uuid.UUID(int=7)}/report", "read", 404, "run-not-found"),
        ("/v1/runs/{run}/report/map-top.png", None, 401, "unauthenticated"),
        # An upload key bound to R1 may read R1's runs, not another robot's.
        ("/v1/runs/{failed}/report", "upload_r1", 403, "forbidden"),
    ],
)
def test_report_errors_are_problems(
    api: Api, fleet: Fleet, path: str, key: str | None, status: int, problem: str
) -> None:
    headers = api.headers(key) if key else {}
    response = api.client.get(path.format(run=fleet.repaired, failed=fleet.failed), headers=headers)
    assert response.status_code == status
    assert problem_type(response) == problem


@sqlite_only
def test_a_robot_key_reads_its_own_report(api: Api, fleet: Fleet) -> None:
    response = api.client.get(
        f"/v1/runs/{fleet.repaired}/report/error.png", headers=api.headers("upload_r1")
    )
    assert response.status_code == 200


# -- exports --------------------------------------------------------------------------------------


@sqlite_only
@pytest.mark.parametrize("fmt", ["tf-static", "urdf", "extrinsics", "autoware"])
def test_text_exports_parse_back_to_the_result(api: Api, fleet: Fleet, fmt: str) -> None:
    response = api.client.get(
        f"/v1/runs/{fleet.repaired}/exports/{fmt}", headers=api.headers("read")
    )
    assert response.status_code == 200, response.text
    disposition = response.headers["content-disposition"]
    assert disposition.startswith(f'attachment; filename="R1-{fleet.repaired.hex[:8]}-')
    assert f"run {fleet.repaired}" in response.text
    parse = {p.value: parser for p, parser in PARSERS.items()}[fmt]
    assert_same(parse(response.text), fleet.documents[fleet.repaired])


@sqlite_only
def test_the_calibrated_recording_reads_back_with_the_new_tf_static(
    api: Api, fleet: Fleet, tmp_path: Path
) -> None:
    scratch_before = set(Path(tempfile.gettempdir()).glob("fleetcal-export-*"))
    response = api.client.get(
        f"/v1/runs/{fleet.repaired}/exports/recording", headers=api.headers("read")
    )
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "application/octet-stream"
    assert 'filename="R1-' in response.headers["content-disposition"]
    assert response.headers["content-disposition"].endswith('calibrated.mcap"')
    path = tmp_path / "calibrated.mcap"
    path.write_bytes(response.content)
    assert_recording_has(path, fleet.documents[fleet.repaired])
    # The request's scratch directory (upload and copy) is gone once the response is sent.
    assert set(Path(tempfile.gettempdir()).glob("fleetcal-export-*")) <= scratch_before


def test_a_failed_verdict_is_exported_only_when_asked(api: Api, fleet: Fleet) -> None:
    refused = api.client.get(f"/v1/runs/{fleet.hit}/exports/urdf", headers=api.headers("read"))
    assert refused.status_code == 409
    assert problem_type(refused) == "not-exportable"
    assert "drift_translation:lidar_rear" in refused.json()["detail"]
    allowed = api.client.get(
        f"/v1/runs/{fleet.hit}/exports/urdf?allow_failed=true", headers=api.headers("read")
    )
    assert allowed.status_code == 200
    assert "verdict FAILED (exported anyway)" in allowed.text


@sqlite_only
@pytest.mark.parametrize(("run", "state"), [("running", "running"), ("failed", "failed")])
def test_a_run_without_result_has_no_export(api: Api, fleet: Fleet, run: str, state: str) -> None:
    response = api.client.get(
        f"/v1/runs/{getattr(fleet, run)}/exports/extrinsics", headers=api.headers("read")
    )
    assert response.status_code == 409
    assert problem_type(response) == "run-has-no-result"
    assert state in response.json()["detail"]


@sqlite_only
def test_an_unknown_export_format_is_a_bad_request(api: Api, fleet: Fleet) -> None:
    response = api.client.get(f"/v1/runs/{fleet.repaired}/exports/sdf", headers=api.headers("read"))
    assert response.status_code == 422
    assert problem_type(response) == "invalid-request"
