"""Drift and deviation checks: distances measured against reference poses, limits that fail the
verdict, and LiDARs the reference knows but the run did not calibrate."""

from __future__ import annotations

import math

import pytest
from scipy.spatial.transform import Rotation

from tests.service.documents import result_document
from workers.context import Reference
from workers.drift import compare

REAR = "lidar_rear"


def moved(translation_m: float, yaw_deg: float) -> Reference:
    """A reference in which the rear LiDAR sat `translation_m` further back, `yaw_deg` turned."""
    calibrated = result_document()["lidars"][REAR]["calibrated"]
    x, y, z = calibrated["translation"]
    rotation = Rotation.from_quat(calibrated["rotation_xyzw"]) * Rotation.from_euler(
        "z", yaw_deg, degrees=True
    )
    return Reference(
        against="last_accepted",
        poses={REAR: ((x - translation_m, y, z), tuple(rotation.as_quat()))},
        max_translation_m=0.01,
        max_rotation_deg=0.5,
        run_id="00000000-0000-0000-0000-000000000001",
    )


def test_drift_within_limits_keeps_the_verdict() -> None:
    document = compare(result_document(), moved(0.004, 0.2))
    drift = document["drift"]["lidars"][REAR]
    assert drift["translation_m"] == pytest.approx(0.004, abs=1e-9)
    assert drift["rotation_deg"] == pytest.approx(0.2, abs=1e-6)
    assert document["drift"]["against"] == "last_accepted"
    assert document["verdict"]["passed"] is True
    names = [check["name"] for check in document["verdict"]["checks"]]
    assert {"drift_translation:lidar_rear", "drift_rotation:lidar_rear"} <= set(names)


@pytest.mark.parametrize(("translation_m", "yaw_deg"), [(0.03, 0.0), (0.0, 2.0)])
def test_a_moved_mount_fails_the_run(translation_m: float, yaw_deg: float) -> None:
    document = compare(result_document(), moved(translation_m, yaw_deg))
    assert document["verdict"]["passed"] is False
    failed = [c["name"] for c in document["verdict"]["checks"] if not c["passed"]]
    expected = "translation" if translation_m else "rotation"
    assert f"drift_{expected}:lidar_rear" in failed


def test_without_limits_drift_is_reported_but_not_judged() -> None:
    reference = Reference(against="design", poses=moved(0.05, 3.0).poses)
    document = compare(result_document(), reference)
    assert document["verdict"] == result_document()["verdict"]
    assert math.isclose(document["drift"]["lidars"][REAR]["translation_m"], 0.05)


def test_a_lidar_of_the_design_that_was_not_calibrated_fails_a_limited_check() -> None:
    design = {
        "lidar_left": ((0.0, 0.3, 0.6), (0.0, 0.0, 0.7071, 0.7071)),
        "lidar_top": ((0.0, 0.0, 1.2), (0.0, 0.0, 0.0, 1.0)),
    }
    reference = Reference(against="design", poses=design, max_translation_m=0.02)
    document = compare(result_document(passed=True), reference)
    assert document["drift"]["missing"] == ["lidar_left", "lidar_top"]
    assert document["verdict"]["passed"] is False
    assert {"design_missing:lidar_left", "design_missing:lidar_top"} <= {
        c["name"] for c in document["verdict"]["checks"] if not c["passed"]
    }
