"""Drift and deviation checks: each LiDAR's calibrated `T_base_lidar` against reference poses (the
robot's last accepted calibration, or its model's design), added to a result's verdict.

A mount that moved or was hit shows as drift; a robot assembled wrong shows as deviation.
"""

from __future__ import annotations

from typing import Any

from pipeline import from_translation_xyzw, pose_difference
from workers.context import Reference

# Check names follow `pipeline.verdict` (`<what>:<frame>`); "deviation" there already means the
# change from the initial extrinsics, hence "design" for the comparison with the design.
_KIND = {"last_accepted": "drift", "design": "design"}


_WHAT = {
    "drift": "last accepted calibration (limit {limit} {unit}): has its mount moved or been hit?",
    "design": "design pose (limit {limit} {unit}): is it mounted as the model says?",
}


def compare(document: dict[str, Any], reference: Reference) -> dict[str, Any]:
    """A copy of `document` with a `drift` section and the limit checks added to its verdict.

    `drift.lidars[frame]` holds the translation (m) and rotation (deg) between the reference pose
    and the calibrated one. A LiDAR the reference knows but the run did not calibrate is listed in
    `drift.missing`, and fails a check when the profile sets a limit: the robot no longer matches.
    """
    kind = _KIND[reference.against]
    lidars: dict[str, dict[str, float]] = {}
    missing: list[str] = []
    checks: list[dict[str, Any]] = []
    calibrated = {
        frame: lidar.get("calibrated") for frame, lidar in document.get("lidars", {}).items()
    }
    limited = reference.max_translation_m is not None or reference.max_rotation_deg is not None
    for frame, (translation, rotation) in sorted(reference.poses.items()):
        pose = calibrated.get(frame)
        if pose is None:
            missing.append(frame)
            if limited:
                checks.append(
                    {
                        "name": f"{kind}_missing:{frame}",
                        "value": None,
                        "limit": None,
                        "passed": False,
                        "detail": f"{frame} is in the {reference.against.replace('_', ' ')} "
                        "extrinsics but was not calibrated",
                    }
                )
            continue
        distance_m, angle_deg = pose_difference(
            from_translation_xyzw(translation, rotation),
            from_translation_xyzw(pose["translation"], pose["rotation_xyzw"]),
        )
        lidars[frame] = {"translation_m": distance_m, "rotation_deg": angle_deg}
        for name, value, limit, unit in (
            (f"{kind}_translation:{frame}", distance_m, reference.max_translation_m, "m"),
            (f"{kind}_rotation:{frame}", angle_deg, reference.max_rotation_deg, "deg"),
        ):
            if limit is None:
                continue
            passed = value <= limit
            detail = (
                ""
                if passed
                else f"{frame} is {value:.4g} {unit} away from its "
                + _WHAT[kind].format(limit=limit, unit=unit)
            )
            checks.append(
                {"name": name, "value": value, "limit": limit, "passed": passed, "detail": detail}
            )
    verdict = dict(document.get("verdict", {}))
    verdict["checks"] = [*verdict.get("checks", []), *checks]
    verdict["passed"] = bool(verdict.get("passed", False)) and all(c["passed"] for c in checks)
    section: dict[str, Any] = {"against": reference.against, "lidars": lidars, "missing": missing}
    if reference.run_id is not None:
        section["run_id"] = reference.run_id
    if reference.measured_at is not None:
        section["measured_at"] = reference.measured_at.isoformat()
    return {**document, "verdict": verdict, "drift": section}
