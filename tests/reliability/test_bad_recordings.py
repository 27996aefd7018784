"""Bad recordings through the worker, on SQLite and PostgreSQL: each passes the upload (its magic
bytes are a recording's) and fails its run at the first attempt with its own problem type, the
stage that found it and a message naming the cause; none is retried, none stays `running`, none
leaves a result or a file outside its scratch folder."""

from __future__ import annotations

import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from service.db import Database
from service.models import RunStatus
from service.settings import Settings
from tests.reliability import recordings
from tests.reliability.harness import QUICK, run_row, store_run, stored_results, wait_for
from tests.workers.runs import running_worker
from workers.worker import CALIBRATE_JOB

# name: (recording, run config, problem type, stage, words the detail must hold)
CASES: dict[str, tuple[Callable[[], bytes], dict[str, Any] | None, str, str | None, str]] = {
    "truncated-mcap": (
        lambda: recordings.truncated(recordings.good_mcap()),
        QUICK,
        "corrupt-recording",
        "read",
        "truncated or damaged",
    ),
    "truncated-ros1": (recordings.ros1_truncated, QUICK, "corrupt-recording", "read", "rosbag"),
    "empty-mcap": (recordings.empty_mcap, QUICK, "empty-recording", "read", "holds no message"),
    "images-only": (recordings.images_only, QUICK, "no-point-cloud", "read", "/camera/image_raw"),
    "nan-clouds": (
        lambda: recordings.non_finite_clouds(float("nan")),
        QUICK,
        "empty-stop-cloud",
        "read",
        "no valid point",
    ),
    "inf-clouds": (
        lambda: recordings.non_finite_clouds(float("inf")),
        QUICK,
        "empty-stop-cloud",
        "read",
        "no valid point",
    ),
    "integer-clouds": (recordings.integer_coordinates, QUICK, "corrupt-recording", "read", "int32"),
    "one-lidar": (recordings.one_lidar, QUICK, "too-few-lidars", "read", "two or more"),
    "no-odometry-no-tf": (recordings.no_trajectory, QUICK, "no-trajectory", "read", "/odom"),
    "nan-odometry": (recordings.nan_odometry, QUICK, "no-trajectory", "read", "usable pose"),
    "no-tf-static": (recordings.no_tf_static, QUICK, "missing-extrinsics", "read", "/tf_static"),
    "never-stops": (recordings.never_stops, QUICK, "no-stops", "read", "never stood still"),
    "zip-traversal": (recordings.zip_traversal, QUICK, "unsafe-archive", "read", "outside"),
    "tar-traversal": (recordings.tar_traversal, QUICK, "unsafe-archive", "read", "outside"),
    "zip-symlink": (recordings.zip_symlink, QUICK, "unsafe-archive", "read", "link"),
    "tar-symlink": (recordings.tar_symlink, QUICK, "unsafe-archive", "read", "link"),
    "tar-hardlink": (recordings.tar_hardlink, QUICK, "unsafe-archive", "read", "link"),
    "zip-bomb": (recordings.zip_bomb, QUICK, "unsafe-archive", "read", "GiB"),
    "tar-gz-bomb": (recordings.tar_gz_bomb, QUICK, "unsafe-archive", "read", "GiB"),
    "config-out-of-range": (
        recordings.good_mcap,
        {"optimisation": {"max_iterations": 0}},
        "invalid-config",
        None,
        "max_iterations",
    ),
    "config-unknown-key": (
        recordings.good_mcap,
        {"optimisation": {"iterations": 5}},
        "invalid-config",
        None,
        "iterations",
    ),
    "config-sets-its-verdict": (
        recordings.good_mcap,
        {"verdict": {"max_metric_error_m": 100}},
        "invalid-config",
        None,
        "tolerance profile",
    ),
    "config-names-missing-lidar": (
        recordings.good_mcap,
        {**QUICK, "reader": {"lidar_topics": ["/velodyne_points", "/lidar_front/points"]}},
        "no-point-cloud",
        "read",
        "/velodyne_points",
    ),
}


@pytest.fixture(scope="module")
def bodies() -> dict[str, bytes]:
    return {name: make() for name, (make, *_) in CASES.items()}


def test_each_bad_recording_fails_its_run_once_with_its_cause(
    settings: Settings, bodies: dict[str, bytes], tmp_path: Path
) -> None:
    db = Database.from_settings(settings)
    escaped = [Path("/tmp/fleetcal-escaped"), Path("/tmp/fleetcal-escaped.mcap")]
    runs: dict[str, uuid.UUID] = {
        name: store_run(settings, db, bodies[name], config=config, max_attempts=3)
        for name, (_, config, *_) in CASES.items()
    }
    final = (RunStatus.SUCCEEDED, RunStatus.FAILED)
    with running_worker(settings, job=CALIBRATE_JOB, concurrency=2):
        wait_for(
            "every bad run to end",
            lambda: all(run_row(db, r).status in final for r in runs.values()),
            timeout=300,
        )
    wrong = {}
    for name, (_, _, slug, stage, words) in CASES.items():
        run = run_row(db, runs[name])
        error = run.error or {}
        seen = (run.status.value, run.attempts, error.get("type"), error.get("stage"))
        expected = ("failed", 1, f"urn:fleetcal:problem:{slug}", stage)
        if seen != expected or words not in error.get("detail", "") or error.get("status") != 422:
            wrong[name] = (seen, error.get("detail"))
        assert stored_results(db, runs[name]) == (0, 0)
    db.dispose()
    assert wrong == {}
    assert not any(path.exists() for path in escaped), "an archive wrote outside its folder"
