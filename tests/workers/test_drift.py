"""Drift and deviation: distances measured against reference poses, judged by the verdict with the
pipeline's checks, and LiDARs the reference knows but the run did not calibrate."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
from scipy.spatial.transform import Rotation

from pipeline.result import result_document
from pipeline.transforms import to_translation_xyzw
from tests.pipeline.calibration_data import dense_box_calibration, floor_only_calibration
from workers.context import Pose, Reference
from workers.drift import compare, judged_against

REAR = "lidar_rear"
RUN = "00000000-0000-0000-0000-000000000001"


def moved(translation_m: float, yaw_deg: float) -> Pose:
    """The rear LiDAR's calibrated pose, `translation_m` further back and turned `yaw_deg`."""
    translation, quaternion = to_translation_xyzw(
        dense_box_calibration().lidar(REAR).T_base_lidar_calibrated
    )
    x, y, z = translation.tolist()
    rotation = Rotation.from_quat(quaternion) * Rotation.from_euler("z", yaw_deg, degrees=True)
    qx, qy, qz, qw = rotation.as_quat().tolist()
    return (x - translation_m, y, z), (qx, qy, qz, qw)


def last_accepted(translation_m: float, yaw_deg: float) -> Reference:
    return Reference(
        against="last_accepted",
        poses={REAR: moved(translation_m, yaw_deg)},
        max_translation_m=0.01,
        max_rotation_deg=0.5,
        run_id=RUN,
        measured_at=datetime(2025, 5, 1, 12, tzinfo=UTC),
    )


def test_drift_within_limits_keeps_the_verdict_and_is_reported() -> None:
    assert dense_box_calibration().verdict.passed
    evidence = compare(dense_box_calibration(), last_accepted(0.004, 0.2))
    assert evidence.lidars[REAR] == pytest.approx((0.004, 0.2), abs=1e-6)
    result = judged_against(dense_box_calibration(), last_accepted(0.004, 0.2))
    assert result.verdict.passed
    document = result_document(result)
    assert document["drift"] == {
        "against": "last_accepted",
        "lidars": {
            REAR: {
                "translation_m": evidence.lidars[REAR][0],
                "rotation_deg": evidence.lidars[REAR][1],
            }
        },
        "missing": [],
        "run_id": RUN,
        "measured_at": "2025-05-01T12:00:00Z",
    }
    names = [check["name"] for check in document["verdict"]["checks"]]
    assert names[-2:] == ["drift_translation:lidar_rear", "drift_rotation:lidar_rear"]
    assert document["stages"] == result_document(dense_box_calibration())["stages"]


@pytest.mark.parametrize(("translation_m", "yaw_deg"), [(0.03, 0.0), (0.0, 2.0)])
def test_a_moved_mount_fails_the_run(translation_m: float, yaw_deg: float) -> None:
    verdict = judged_against(dense_box_calibration(), last_accepted(translation_m, yaw_deg)).verdict
    assert not verdict.passed
    expected = "translation" if translation_m else "rotation"
    assert [check.name for check in verdict.failed] == [f"drift_{expected}:lidar_rear"]
    assert "has its mount moved or been hit?" in verdict.failed[0].detail


def test_without_limits_drift_is_reported_but_not_judged() -> None:
    reference = Reference(against="design", poses={REAR: moved(0.05, 3.0)})
    result = judged_against(dense_box_calibration(), reference)
    assert result.verdict == dense_box_calibration().verdict
    assert result_document(result)["drift"]["lidars"][REAR]["translation_m"] == pytest.approx(0.05)


def test_a_lidar_of_the_design_that_was_not_calibrated_fails_a_limited_check() -> None:
    design = {
        REAR: ((-0.5, 0.0, 0.6), (0.0, 0.0, 0.0, 1.0)),  # undetermined by the data
        "lidar_top": ((0.0, 0.0, 1.2), (0.0, 0.0, 0.0, 1.0)),  # not on this robot
    }
    reference = Reference(against="design", poses=design, max_translation_m=0.02)
    assert compare(floor_only_calibration(), reference).missing == (REAR, "lidar_top")
    verdict = judged_against(floor_only_calibration(), reference).verdict
    assert {"design_missing:lidar_rear", "design_missing:lidar_top"} <= {
        check.name for check in verdict.failed
    }


def test_an_unknown_reference_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="expected one of"):
        compare(dense_box_calibration(), Reference(against="yesterday", poses={}))
