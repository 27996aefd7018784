"""End to end on SQLite and PostgreSQL, with the real pipeline on the synthesiser's `tiny` scenario:
upload through the HTTP API -> worker -> result with verdict; the run, history and calibration
endpoints agree; a maintenance run reports drift; a bad recording fails with its cause; a worker
killed with SIGKILL mid-run loses nothing and duplicates nothing."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import tarfile
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import Any

import httpx
import jsonschema
import pytest
from sqlalchemy import func, select

from pipeline.calibrate import STAGES
from pipeline.result import result_schema
from service.auth import create_key
from service.db import Database
from service.models import LidarExtrinsic, Result, RunStatus, Scope
from service.settings import Settings
from tests.service.conftest import scratch_pg_database
from tests.service.documents import result_document
from tests.workers.runs import (
    ROOT,
    entrypoint_env,
    finished_run,
    run_row,
    running_worker,
    wait_for,
)
from workers.embedded import EmbeddedService
from workers.worker import CALIBRATE_JOB, WorkerOptions

ROBOT = "R1"
# Sent as X-Fleetcal-Config; the worker must pass it to the pipeline (it shows in the result).
RUN_CONFIG = {"frames": {"reference_frame": "lidar_front"}}
# Wide limits for the tiny scenario's few points, and drift limits for maintenance runs.
PROFILE = {
    "robot_model": "tiny-bot",
    "limits": {
        "max_metric_error_m": 0.5,
        "max_translation_stddev_m": 1.0,
        "max_rotation_stddev_deg": 10.0,
        "max_translation_drift_m": 0.05,
        "max_rotation_drift_deg": 2.0,
    },
}
FINAL = ("succeeded", "failed")


@pytest.fixture(scope="session")
def tiny_recording(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """The `tiny` scenario's ROS 2 bag directory as a robot uploads it: one tar archive."""
    from pipeline.synth import write_recording
    from pipeline.synth.recording import archive_recording

    scratch = tmp_path_factory.mktemp("tiny")
    write_recording("tiny", scratch / "synth", seed=0)
    return archive_recording(scratch / "synth", scratch / "recording.tar").read_bytes()


@dataclass
class Fleet:
    """A robot's view of the service (its upload key) and an operator's (an admin key)."""

    robot: httpx.Client
    admin: httpx.Client
    db: Database

    def upload(self, body: bytes, kind: str = "end_of_line", config: Any = RUN_CONFIG) -> str:
        response = self.robot.post(
            f"/v1/robots/{ROBOT}/runs",
            params={"kind": kind},
            content=body,
            headers={
                "Idempotency-Key": str(uuid.uuid4()),
                "X-Fleetcal-Config": json.dumps(config),
            },
        )
        assert response.status_code == 202, response.text
        return str(response.json()["id"])

    def follow(self, run_id: str) -> tuple[dict[str, Any], list[str]]:
        """Poll the run until it ends, as a robot does; the stages seen on the way."""
        seen: list[str] = []

        def ended() -> bool:
            run = self.robot.get(f"/v1/runs/{run_id}").raise_for_status().json()
            if run["stage"] and run["stage"] not in seen:
                seen.append(run["stage"])
            return run["status"] in FINAL

        wait_for(f"run {run_id}", ended, timeout=300)
        return self.robot.get(f"/v1/runs/{run_id}").json(), seen


@contextlib.contextmanager
def make_fleet(settings: Settings, base_url: str) -> Iterator[Fleet]:
    db = Database.from_settings(settings)
    db.upgrade()
    with db.transaction() as session:
        admin = create_key(session, [Scope.ADMIN]).secret
        robot = create_key(session, [Scope.UPLOAD], robot_id=ROBOT).secret
    with (
        httpx.Client(base_url=base_url, headers={"X-API-Key": robot}, timeout=60) as robot_client,
        httpx.Client(base_url=base_url, headers={"X-API-Key": admin}, timeout=60) as admin_client,
    ):
        admin_client.put("/v1/tolerance-profiles/tiny", json=PROFILE).raise_for_status()
        admin_client.put(f"/v1/robots/{ROBOT}", json={"model": "tiny-bot"}).raise_for_status()
        yield Fleet(robot_client, admin_client, db)
    db.dispose()


@pytest.fixture
def embedded(settings: Settings) -> Iterator[Fleet]:
    """`fleetcal serve` in this process: the API and one pipeline process."""
    options = WorkerOptions(poll_interval=timedelta(milliseconds=100))
    with (
        EmbeddedService(settings, port=0, workers=1, options=options) as service,
        make_fleet(settings, service.url) as fleet,
    ):
        yield fleet


@pytest.fixture
def api_only(settings: Settings) -> Iterator[Fleet]:
    """The API alone: the test starts and kills its workers."""
    with (
        EmbeddedService(settings, port=0, workers=0) as service,
        make_fleet(settings, service.url) as fleet,
    ):
        yield fleet


def pose(entry: dict[str, Any]) -> tuple[list[float], list[float]]:
    return list(entry["translation"]), list(entry["rotation_xyzw"])


@pytest.mark.slow
def test_upload_to_verdict_and_the_endpoints_agree(
    api_only: Fleet, settings: Settings, tiny_recording: bytes
) -> None:
    """A maintenance run: its result, drift from the accepted calibration before it, and what the
    run, list, history and calibration endpoints say about it, all consistent."""
    fleet = api_only
    # Calibrated last month; recorded before any worker runs, so that none takes it.
    accepted = str(finished_run(fleet.db, result_document(), ROBOT))
    run_id = fleet.upload(tiny_recording, kind="maintenance")
    with running_worker(settings, job=CALIBRATE_JOB, poll_interval=timedelta(milliseconds=100)):
        run, stages_seen = fleet.follow(run_id)
    assert run["status"] == "succeeded", run["error"]
    assert run["attempts"] == 1 and run["progress"] == 1.0 and run["stage"] is None
    assert set(stages_seen) & set(STAGES), f"progress never showed a pipeline stage: {stages_seen}"

    result = run["result"]
    jsonschema.validate(result, result_schema())
    assert result["config"]["frames"]["reference_frame"] == "lidar_front", "the upload's config"
    assert result["tolerance_profile"] == "tiny"
    checks = {check["name"]: check for check in result["verdict"]["checks"]}
    assert checks["metric_error"]["limit"] == 0.5, "the profile sets the verdict's limits"
    for stage in ("download", "read", "denoise", "optimisation"):
        assert result["stages"][stage]["seconds"] >= 0
    verdict = result["verdict"]["passed"]
    assert verdict == all(check["passed"] for check in checks.values()) == run["passed"]

    # Drift: against the accepted calibration, per LiDAR, with the profile's limits.
    drift = result["drift"]
    assert drift["against"] == "last_accepted" and drift["run_id"] == accepted
    calibrated = {
        frame: pose(lidar["calibrated"])
        for frame, lidar in result["lidars"].items()
        if lidar["calibrated"] is not None
    }
    for frame in ("lidar_front", "lidar_rear"):
        if frame in calibrated:
            assert checks[f"drift_translation:{frame}"]["limit"] == 0.05
            value = checks[f"drift_translation:{frame}"]["value"]
            assert value == drift["lidars"][frame]["translation_m"]
        else:
            assert frame in drift["missing"] and not checks[f"drift_missing:{frame}"]["passed"]

    listed = fleet.admin.get("/v1/runs", params={"robot_id": ROBOT}).raise_for_status().json()
    assert [(i["id"], i["passed"]) for i in listed["items"]] == [
        (run_id, verdict),
        (accepted, True),
    ]
    assert listed["items"][0]["metric_error_final"] == result["metric_error"]["final"]

    history = fleet.robot.get(f"/v1/robots/{ROBOT}/history").raise_for_status().json()
    rows = [item for item in history["items"] if item["run_id"] == run_id]
    assert {item["frame"]: pose(item) for item in rows} == calibrated
    assert {item["passed"] for item in rows} <= {verdict}

    calibration = fleet.robot.get(f"/v1/robots/{ROBOT}/calibration").raise_for_status().json()
    newest_accepted = run_id if verdict else accepted
    assert calibration["run_id"] == newest_accepted
    if verdict:
        assert calibration["result"] == result
        assert {f: pose(lidar) for f, lidar in calibration["lidars"].items()} == calibrated


@pytest.mark.parametrize("damage", ["truncated", "not a bag"])
def test_a_bad_recording_fails_the_run_with_its_cause(
    embedded: Fleet, tiny_recording: bytes, damage: str
) -> None:
    if damage == "truncated":
        body, cause = tiny_recording[: len(tiny_recording) // 3], "corrupt-recording"
    else:
        # Passes the upload's magic-byte check (a tar holding a text file), holds no bag.
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as tar:
            note = tarfile.TarInfo("notes.txt")
            note.size = 5
            tar.addfile(note, io.BytesIO(b"hello"))
        body, cause = buffer.getvalue(), "unknown-format"
    run, _ = embedded.follow(embedded.upload(body))
    assert run["status"] == "failed" and run["attempts"] == 1
    assert run["result"] is None and run["passed"] is None
    error = run["error"]
    assert error["type"] == f"urn:fleetcal:problem:{cause}", error
    assert error["status"] == 422 and error["stage"] == "read" and error["detail"]


def result_rows(db: Database, run_id: str) -> tuple[int, int]:
    with db.session() as session:
        results = session.scalar(
            select(func.count()).select_from(Result).where(Result.run_id == uuid.UUID(run_id))
        )
        extrinsics = session.scalar(
            select(func.count())
            .select_from(LidarExtrinsic)
            .where(LidarExtrinsic.run_id == uuid.UUID(run_id))
        )
    return int(results or 0), int(extrinsics or 0)


@pytest.mark.slow
def test_a_worker_killed_mid_run_loses_nothing_and_duplicates_nothing(
    api_only: Fleet, settings: Settings, tiny_recording: bytes
) -> None:
    """`fleetcal worker` is killed with SIGKILL (with its pipeline process) while it calibrates;
    the run stays `running` until its lease expires, then another worker finishes it, once."""
    fleet = api_only
    short_lease = settings.model_copy(update={"run_lease_seconds": 2})
    run_id = fleet.upload(tiny_recording)
    env = entrypoint_env(
        FLEETCAL_DATABASE_URL=settings.resolved_database_url,
        FLEETCAL_STORAGE_URL=settings.resolved_storage_url,
        FLEETCAL_RUN_LEASE_SECONDS="2",
    )
    doomed = subprocess.Popen(
        ["fleetcal", "worker", "--concurrency", "1"],
        env=env,
        cwd=ROOT,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(
            "the pipeline to start",
            lambda: run_row(fleet.db, uuid.UUID(run_id)).stage in STAGES,
            timeout=120,
        )
    finally:
        os.killpg(doomed.pid, signal.SIGKILL)
        doomed.wait()
    row = run_row(fleet.db, uuid.UUID(run_id))
    assert row.status == RunStatus.RUNNING and row.attempts == 1, "nobody finished it"

    with running_worker(short_lease, job=CALIBRATE_JOB):
        run, _ = fleet.follow(run_id)
    assert run["status"] == "succeeded" and run["attempts"] == 2, run["error"]
    determined = sorted(
        frame for frame, lidar in run["result"]["lidars"].items() if lidar["calibrated"]
    )
    assert result_rows(fleet.db, run_id) == (1, len(determined)), "one result, a row per LiDAR"
    history = fleet.robot.get(f"/v1/robots/{ROBOT}/history").json()
    assert sorted(item["frame"] for item in history["items"]) == determined


@pytest.mark.postgres
@pytest.mark.slow
def test_the_distributed_setup_postgresql_and_s3(
    s3_endpoint: str, tiny_recording: bytes, tmp_path: Path
) -> None:
    """The compose deployment without Docker: PostgreSQL, an S3-compatible server, the API, and a
    separate `fleetcal worker` process that reads the recording from the bucket."""
    import boto3

    credentials = {
        "AWS_ACCESS_KEY_ID": "test",
        "AWS_SECRET_ACCESS_KEY": "test",
        "AWS_DEFAULT_REGION": "us-east-1",
    }
    bucket = f"fleetcal-{uuid.uuid4().hex[:8]}"
    boto3.client(
        "s3",
        endpoint_url=s3_endpoint,
        aws_access_key_id="test",
        aws_secret_access_key="test",
        region_name="us-east-1",
    ).create_bucket(Bucket=bucket)
    with scratch_pg_database() as database_url, pytest.MonkeyPatch.context() as patch:
        for name, value in credentials.items():
            patch.setenv(name, value)
        settings = Settings(
            data_dir=tmp_path / "data",
            database_url=database_url,
            storage_url=f"s3://{bucket}/recordings",
            s3_endpoint_url=s3_endpoint,
            max_upload_bytes=256 * 1024 * 1024,
        )
        env = entrypoint_env(
            FLEETCAL_DATABASE_URL=database_url,
            FLEETCAL_STORAGE_URL=settings.resolved_storage_url,
            FLEETCAL_S3_ENDPOINT_URL=s3_endpoint,
            FLEETCAL_MIGRATE_ON_START="false",
            **credentials,
        )
        with (
            EmbeddedService(settings, port=0, workers=0) as service,
            make_fleet(settings, service.url) as fleet,
        ):
            run_id = fleet.upload(tiny_recording)
            worker = subprocess.Popen(
                ["fleetcal", "worker", "--concurrency", "1"],
                env=env,
                cwd=ROOT,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
            try:
                run, _ = fleet.follow(run_id)
            finally:
                worker.send_signal(signal.SIGTERM)
                _, err = worker.communicate(timeout=120)
    assert worker.returncode == 0, err
    assert run["status"] == "succeeded", run["error"]
    assert run["result"]["stages"]["download"]["seconds"] >= 0
    assert not (tmp_path / "data" / "storage").exists(), "nothing went to local storage"
