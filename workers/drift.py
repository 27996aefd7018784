"""Drift and deviation: each LiDAR's calibrated `T_base_lidar` measured against reference poses
(the robot's last accepted calibration, or its model's design), judged by the verdict.

A mount that moved or was hit shows as drift; a robot assembled wrong shows as deviation. The
distances are evidence (`pipeline.verdict.DriftEvidence`); `pipeline.verdict` judges them with the
pipeline's own checks, and `result.json` reports them in its `drift` section.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Literal

from pipeline import (
    CalibrationResult,
    DriftEvidence,
    from_translation_xyzw,
    pose_difference,
    to_translation_xyzw,
    with_drift,
)
from workers.context import Reference

_AGAINST: dict[str, Literal["last_accepted", "design"]] = {
    "last_accepted": "last_accepted",
    "design": "design",
}


def compare(result: CalibrationResult, reference: Reference) -> DriftEvidence:
    """How far each LiDAR the reference knows is from its reference pose, translation (m) and
    rotation (deg), with the profile's limits. A LiDAR the reference knows but the run did not
    calibrate (absent, or undetermined by the data) is `missing`."""
    against = _AGAINST.get(reference.against)
    if against is None:
        raise ValueError(
            f"reference poses against {reference.against!r}: expected one of {sorted(_AGAINST)}"
        )
    calibrated = {
        lidar.frame: lidar.T_base_lidar_calibrated
        for lidar in result.lidars
        if not lidar.uncertainty.undetermined
    }
    lidars: dict[str, tuple[float, float]] = {}
    missing: list[str] = []
    for frame, (translation, rotation) in sorted(reference.poses.items()):
        if frame not in calibrated:
            missing.append(frame)
            continue
        # The pose as `result.json` writes it (a unit quaternion, w >= 0): what the robot reads.
        written = from_translation_xyzw(*to_translation_xyzw(calibrated[frame]))
        lidars[frame] = pose_difference(from_translation_xyzw(translation, rotation), written)
    return DriftEvidence(
        against=against,
        lidars=lidars,
        missing=tuple(missing),
        max_translation_m=reference.max_translation_m,
        max_rotation_deg=reference.max_rotation_deg,
        run_id=reference.run_id,
        measured_at=reference.measured_at,
    )


def judged_against(result: CalibrationResult, reference: Reference) -> CalibrationResult:
    """`result` with its verdict judged again with the drift from `reference` as evidence."""
    return replace(result, verdict=with_drift(result.verdict, compare(result, reference)))
