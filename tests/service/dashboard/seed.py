"""A small fleet for the dashboard and export tests, written through the data layer and storage
the way the API and the worker write it: a real recording per run, result documents, report
images drawn from the `tiny` scenario, a tolerance profile with drift limits, and one run of
each state.

R1 (model demo-bot): end-of-line passed 20 days ago, maintenance 10 days ago failed on drift (a
hit mount), maintenance yesterday passed again. R2: a run that failed (no stops). R3: a run in
progress. R4 (demo-bot): two accepted calibrations 3 and 2 days ago, then a maintenance run 2 h
ago whose optimisation diverged (the rear LiDAR 250 mm and 4 deg off, metric error and
convergence failed): the newest run, and no calibration. R5: an end-of-line run on a floor with
no objects in the rear LiDAR's view, every check of the pipeline's verdict, the rear LiDAR's x
and yaw undetermined.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from pipeline.io.writer import WriterFormat
from pipeline.report import render
from pipeline.synth import simulate_problem
from pipeline.transforms import Matrix4, from_xyz_rpy, pose_difference, to_translation_xyzw
from service import repository
from service.db import Database
from service.models import Run, RunKind, RunStatus
from service.reports import store_report_images
from service.storage import Storage
from tests.pipeline.io.recordings import PERTURBATION, TRUE_EXTRINSICS, Spec, write_recording
from tests.pipeline.test_report import truth_report_input
from tests.service.uploads import new_upload

PROFILE_LIMITS = {
    "max_metric_error_m": 0.01,
    "max_translation_drift_m": 0.01,
    "max_rotation_drift_deg": 0.5,
}
INITIAL = {frame: T @ PERTURBATION for frame, T in TRUE_EXTRINSICS.items()}
DIVERGED = {
    "lidar_front": TRUE_EXTRINSICS["lidar_front"],
    "lidar_rear": TRUE_EXTRINSICS["lidar_rear"] @ from_xyz_rpy([0.25, 0, 0], [0, 0, 0.07]),
}
HIT = {  # the rear mount knocked 15 mm and 0.8 deg
    "lidar_front": TRUE_EXTRINSICS["lidar_front"],
    "lidar_rear": TRUE_EXTRINSICS["lidar_rear"] @ from_xyz_rpy([0.015, 0, 0], [0, 0, 0.014]),
}
REPAIRED = {
    "lidar_front": TRUE_EXTRINSICS["lidar_front"],
    "lidar_rear": TRUE_EXTRINSICS["lidar_rear"] @ from_xyz_rpy([0.002, -0.001, 0], [0, 0.001, 0]),
}
STAGES = {
    "download": 0.02,
    "read": 0.31,
    "denoise": 0.42,
    "segmentation": 0.55,
    "rough_refinement": 0.08,
    "optimisation": 1.93,
    "metric": 0.02,
    "observability": 0.01,
    "verdict": 0.0,
}


@dataclass(frozen=True)
class Fleet:
    """The seeded runs' ids and what their results say."""

    end_of_line: uuid.UUID
    hit: uuid.UUID
    repaired: uuid.UUID
    failed: uuid.UUID
    running: uuid.UUID
    r4_accepted: tuple[uuid.UUID, uuid.UUID]
    diverged: uuid.UUID
    undetermined: uuid.UUID
    documents: dict[uuid.UUID, dict[str, Any]]


def report_images() -> dict[str, bytes]:
    """The report of the `tiny` scenario: recorded poses before, the synthesiser's truth after."""
    return render(truth_report_input(*simulate_problem("tiny", seed=0)))


def recording_bytes(scratch: Path) -> bytes:
    """A small ROS 2 MCAP recording whose tf_static holds `INITIAL` (rear LiDAR via a mount)."""
    bag = scratch / "seed_recording"
    write_recording(bag, WriterFormat.ROS2_MCAP, Spec(stops=2, points=200))
    return (bag / "seed_recording.mcap").read_bytes()


def pose(T: Matrix4) -> dict[str, list[float]]:
    translation, quat = to_translation_xyzw(T)
    return {"translation": translation.tolist(), "rotation_xyzw": quat.tolist()}


def result_document(
    calibrated: dict[str, Matrix4],
    *,
    metric: tuple[float, float],
    checks: list[dict[str, Any]],
    drift_from: dict[str, Matrix4] | None = None,
    drift_run: uuid.UUID | None = None,
) -> dict[str, Any]:
    """A `result.json` as the worker stores it (DESIGN.md's output contract)."""
    passed = all(check["passed"] for check in checks)
    document: dict[str, Any] = {
        "schema_version": 1,
        "reference_frame": "lidar_front",
        "base_frame": "base_link",
        "lidars": {
            frame: {
                "topic": f"/{frame}/points",
                "initial": pose(INITIAL[frame]),
                "calibrated": pose(T),
                "stddev": {"translation_m": [0.0008, 0.0007, 0.0011], "rotation_deg": [0.02] * 3},
            }
            for frame, T in calibrated.items()
        },
        "metric_error": {"initial": metric[0], "final": metric[1]},
        "verdict": {"passed": passed, "checks": checks},
        "stages": {name: {"seconds": seconds} for name, seconds in STAGES.items()},
        "pipeline_version": "0.1.0",
        "config_hash": "sha256:" + "5e" * 32,
        "tolerance_profile": "demo-bot",
        "report": {"images": ["map-top", "map-side", "error"]},
    }
    if drift_from is not None:
        differences = {
            frame: pose_difference(drift_from[frame], T) for frame, T in calibrated.items()
        }
        document["drift"] = {
            "against": "last_accepted",
            "run_id": str(drift_run),
            "lidars": {
                frame: {"translation_m": t, "rotation_deg": r}
                for frame, (t, r) in differences.items()
            },
            "missing": [],
        }
    return document


def pipeline_checks(
    metric: float, *, iterations: int, converged: bool, rear_points: int, undetermined: list[str]
) -> list[dict[str, Any]]:
    """Every check `pipeline.verdict.judge` makes for the two LiDARs, with its default limits."""

    def check(name: str, value: float, limit: float, passed: bool, detail: str) -> dict[str, Any]:
        return {"name": name, "value": value, "limit": limit, "passed": passed, "detail": detail}

    stddev_t = 4.9 if undetermined else 0.0011
    stddev_r = 61.0 if undetermined else 0.02
    return [
        metric_check(metric, limit=0.04),
        check(
            "convergence",
            float(iterations),
            200.0,
            converged,
            "" if converged else "no convergence within 200 iterations",
        ),
        check("object_points:lidar_front", 18100.0, 200.0, True, ""),
        check("object_points:lidar_rear", float(rear_points), 200.0, rear_points >= 200, ""),
        {
            **check(
                "determined:lidar_rear",
                float(len(undetermined)),
                0.0,
                not undetermined,
                f"the data do not determine {', '.join(undetermined)} of lidar_rear"
                if undetermined
                else "",
            ),
            **({"dofs": undetermined} if undetermined else {}),
        },
        check("uncertainty_translation:lidar_rear", stddev_t, 0.005, stddev_t <= 0.005, ""),
        check("uncertainty_rotation:lidar_rear", stddev_r, 0.1, stddev_r <= 0.1, ""),
    ]


def metric_check(value: float, limit: float = 0.01) -> dict[str, Any]:
    return {
        "name": "metric_error",
        "value": value,
        "limit": limit,
        "passed": value <= limit,
        "detail": "",
    }


def drift_checks(
    calibrated: dict[str, Matrix4], reference: dict[str, Matrix4]
) -> list[dict[str, Any]]:
    checks = []
    for frame, T in sorted(calibrated.items()):
        t, r = pose_difference(reference[frame], T)
        for name, value, limit, unit in (
            (f"drift_translation:{frame}", t, PROFILE_LIMITS["max_translation_drift_m"], "m"),
            (f"drift_rotation:{frame}", r, PROFILE_LIMITS["max_rotation_drift_deg"], "deg"),
        ):
            passed = value <= limit
            checks.append(
                {
                    "name": name,
                    "value": value,
                    "limit": limit,
                    "passed": passed,
                    "detail": ""
                    if passed
                    else f"{frame} is {value:.4g} {unit} away from its "
                    "last accepted calibration: has its mount moved or been hit?",
                }
            )
    return checks


def seed_fleet(db: Database, storage: Storage, recording: bytes, images: dict[str, bytes]) -> Fleet:
    fleet = _Seeding(db, storage, recording, images, datetime.now(UTC))
    _seed_profile(db)
    eol, hit, repaired = _seed_r1(fleet)
    failed = _seed_failed(fleet)
    running = _seed_running(fleet)
    r4 = _seed_r4(fleet)
    undetermined = fleet.upload("R5", RunKind.END_OF_LINE, timedelta(hours=5))
    fleet.documents[undetermined] = undetermined_document()
    with db.transaction() as session:
        repository.store_result(session, undetermined, fleet.documents[undetermined])
    return Fleet(eol, hit, repaired, failed, running, r4[:2], r4[2], undetermined, fleet.documents)


@dataclass(frozen=True)
class _Seeding:
    """What the seeded runs share: where they are written, the recording and report images
    each has, the time the fleet is seeded at, and the result documents stored so far."""

    db: Database
    storage: Storage
    recording: bytes
    images: dict[str, bytes]
    now: datetime
    documents: dict[uuid.UUID, dict[str, Any]] = field(default_factory=dict)

    def upload(self, robot: str, kind: RunKind, ago: timedelta) -> uuid.UUID:
        """A run of `robot` as if its recording had come in `ago` before now."""
        return _upload(self.db, self.storage, self.recording, robot, kind, self.now - ago)


def _seed_profile(db: Database) -> None:
    """The `demo-bot` tolerance profile with drift limits, and its robots R1 and R4."""
    with db.transaction() as session:
        repository.put_tolerance_profile(
            session,
            "demo-bot",
            robot_model="demo-bot",
            is_default=False,
            limits=PROFILE_LIMITS,
            design_extrinsics=None,
        )
        repository.put_robot(session, "R1", model="demo-bot", metadata={"site": "line 2"})
        repository.put_robot(session, "R4", model="demo-bot", metadata={"site": "line 3"})


def _seed_r1(fleet: _Seeding) -> tuple[uuid.UUID, uuid.UUID, uuid.UUID]:
    """End-of-line 20 days ago, a maintenance run failed on drift (a hit mount) 10 days ago,
    one passed again yesterday; their results stored with report images and stage times."""
    documents = fleet.documents
    eol = fleet.upload("R1", RunKind.END_OF_LINE, timedelta(days=20))
    documents[eol] = result_document(
        TRUE_EXTRINSICS, metric=(0.0912, 0.0015), checks=[metric_check(0.0015)]
    )
    hit = fleet.upload("R1", RunKind.MAINTENANCE, timedelta(days=10))
    documents[hit] = result_document(
        HIT,
        metric=(0.0261, 0.0016),
        checks=[metric_check(0.0016), *drift_checks(HIT, TRUE_EXTRINSICS)],
        drift_from=TRUE_EXTRINSICS,
        drift_run=eol,
    )
    repaired = fleet.upload("R1", RunKind.MAINTENANCE, timedelta(days=1))
    documents[repaired] = result_document(
        REPAIRED,
        metric=(0.0203, 0.0014),
        checks=[metric_check(0.0014), *drift_checks(REPAIRED, TRUE_EXTRINSICS)],
        drift_from=TRUE_EXTRINSICS,
        drift_run=eol,
    )
    for run_id in (eol, hit, repaired):
        store_report_images(fleet.storage, run_id, fleet.images)
        with fleet.db.transaction() as session:
            repository.store_result(session, run_id, documents[run_id])
            _took(session, run_id, seconds=sum(STAGES.values()))
    return eol, hit, repaired


def _seed_failed(fleet: _Seeding) -> uuid.UUID:
    """R2's run 3 h ago, failed: the recording has no stops."""
    failed = fleet.upload("R2", RunKind.END_OF_LINE, timedelta(hours=3))
    with fleet.db.transaction() as session:
        repository.fail_run(
            session,
            failed,
            {
                "type": "urn:fleetcal:problem:bad-recording",
                "title": "The recording cannot be calibrated",
                "status": 422,
                "detail": "no stops found in the trajectory: the robot never stood still for 1 s",
            },
        )
        _took(session, failed, seconds=0.4)
    return failed


def _seed_running(fleet: _Seeding) -> uuid.UUID:
    """R3's run uploaded 2 min ago, in its optimisation now."""
    running = fleet.upload("R3", RunKind.END_OF_LINE, timedelta(minutes=2))
    with fleet.db.transaction() as session:
        run = session.get(Run, running)
        assert run is not None
        run.status, run.attempts, run.started_at = RunStatus.RUNNING, 1, fleet.now
        run.stage, run.progress = "optimisation", 0.45
    return running


def _seed_r4(fleet: _Seeding) -> tuple[uuid.UUID, uuid.UUID, uuid.UUID]:
    """Two accepted calibrations (3 and 2 days ago), then a diverged one 2 h ago."""
    ids = []
    for days_ago, calibrated, metric, kind in (
        (3.0, TRUE_EXTRINSICS, 0.0015, RunKind.END_OF_LINE),
        (2.0, REPAIRED, 0.0014, RunKind.MAINTENANCE),
        (2 / 24, DIVERGED, 0.052, RunKind.MAINTENANCE),
    ):
        run_id = fleet.upload("R4", kind, timedelta(days=days_ago))
        diverged = calibrated is DIVERGED
        fleet.documents[run_id] = result_document(
            calibrated,
            metric=(0.031, metric),
            checks=pipeline_checks(
                metric,
                iterations=200 if diverged else 22,
                converged=not diverged,
                rear_points=9350,
                undetermined=[],
            ),
        )
        store_report_images(fleet.storage, run_id, fleet.images)
        with fleet.db.transaction() as session:
            repository.store_result(session, run_id, fleet.documents[run_id])
        ids.append(run_id)
    return ids[0], ids[1], ids[2]


def undetermined_document() -> dict[str, Any]:
    """The rear LiDAR saw only the floor: x and yaw undetermined, no calibrated pose."""
    undetermined = ["x", "yaw"]
    document = result_document(
        TRUE_EXTRINSICS,
        metric=(0.0, 0.0),
        checks=pipeline_checks(
            0.0, iterations=12, converged=True, rear_points=40, undetermined=undetermined
        ),
    )
    document["metric_error"] = {"initial": None, "final": None}
    document["verdict"]["checks"][0].update(value=None, passed=False)
    document["verdict"]["passed"] = False
    rear = document["lidars"]["lidar_rear"]
    rear["calibrated"] = None
    rear["undetermined"] = undetermined
    rear["stddev"] = {"translation_m": [None, 0.0007, 0.0011], "rotation_deg": [0.02, 0.02, None]}
    document["report"] = {"images": []}
    return document


def _took(session: Any, run_id: uuid.UUID, seconds: float) -> None:
    run = session.get(Run, run_id)
    run.started_at = run.created_at + timedelta(seconds=1)
    run.finished_at = run.started_at + timedelta(seconds=seconds)


def _upload(
    db: Database, storage: Storage, recording: bytes, robot: str, kind: RunKind, at: datetime
) -> uuid.UUID:
    run_id = uuid.uuid4()
    key = f"recordings/{robot}/{run_id}"
    upload = storage.begin_upload(key)
    upload.write(recording)
    upload.commit()
    with db.transaction() as session:
        run = repository.record_upload(
            session,
            new_upload(robot, run_id=run_id, kind=kind, body=recording, storage_key=key),
            create_robot=True,
        )
        # History is about time: each run as if uploaded `at`.
        run.created_at = run.available_at = run.updated_at = at
    return run_id
