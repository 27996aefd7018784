"""What an attempt needs besides its recording, read from the database when the run is claimed:
the robot's tolerance profile, and the poses its extrinsics are compared with (the last accepted
calibration for a maintenance run, the model's design for an end-of-line run), all in a `JobSpec`.

Plain, picklable records: the child process that runs the pipeline never touches the database.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from service import repository
from service.models import LidarExtrinsic, Result, Robot, RunKind
from service.settings import Settings
from workers.queue import Claim

Pose = tuple[tuple[float, float, float], tuple[float, float, float, float]]
"""`T_base_lidar` as (translation, rotation_xyzw)."""


@dataclass(frozen=True)
class Reference:
    """Poses to compare the calibrated extrinsics with, and the limits of the difference."""

    against: str
    """`last_accepted` (maintenance: drift) or `design` (end of line: deviation)."""
    poses: dict[str, Pose]
    max_translation_m: float | None = None
    max_rotation_deg: float | None = None
    run_id: str | None = None
    measured_at: datetime | None = None


@dataclass(frozen=True)
class RunContext:
    profile: str | None = None
    limits: dict[str, float] = field(default_factory=dict)
    """The profile's `ToleranceLimits` that are set (`service.schemas.ToleranceLimits`)."""
    reference: Reference | None = None


@dataclass(frozen=True)
class JobSpec:
    """Everything the child needs: the run, where its recording is, and its verdict context."""

    run_id: str
    attempt: int
    robot_id: str
    kind: str
    storage_key: str
    upload_format: str
    config: dict[str, Any] | None
    settings: Settings
    context: RunContext = field(default_factory=RunContext)


def load_context(session: Session, claim: Claim) -> RunContext:
    robot = session.get(Robot, claim.robot_id)
    profile = repository.tolerance_profile_for(session, robot) if robot is not None else None
    limits: dict[str, Any] = dict(profile.limits) if profile is not None else {}
    reference: Reference | None = None
    if claim.kind == RunKind.MAINTENANCE:
        reference = _last_accepted(session, claim, limits)
    elif profile is not None and profile.design_extrinsics:
        reference = Reference(
            against="design",
            poses={
                frame: (tuple(pose["translation"]), tuple(pose["rotation_xyzw"]))
                for frame, pose in profile.design_extrinsics.items()
            },
            max_translation_m=limits.get("max_translation_deviation_m"),
            max_rotation_deg=limits.get("max_rotation_deviation_deg"),
        )
    return RunContext(
        profile=profile.name if profile is not None else None, limits=limits, reference=reference
    )


def _last_accepted(session: Session, claim: Claim, limits: dict[str, Any]) -> Reference | None:
    """The robot's newest accepted calibration (passed, or accepted by an operator, and not
    rejected) recorded before this run's upload: a retried or late run compares with what was
    accepted before it, not with a newer run."""
    result = session.scalar(
        select(Result)
        .where(
            Result.robot_id == claim.robot_id,
            Result.accepted.is_(True),
            Result.measured_at < claim.created_at,
            Result.run_id != claim.run_id,
        )
        .order_by(Result.measured_at.desc(), Result.run_id.desc())
        .limit(1)
    )
    if result is None:
        return None
    rows = session.scalars(select(LidarExtrinsic).where(LidarExtrinsic.run_id == result.run_id))
    return Reference(
        against="last_accepted",
        poses={
            row.frame: ((row.tx, row.ty, row.tz), (row.qx, row.qy, row.qz, row.qw)) for row in rows
        },
        max_translation_m=limits.get("max_translation_drift_m"),
        max_rotation_deg=limits.get("max_rotation_drift_deg"),
        run_id=str(result.run_id),
        measured_at=result.measured_at,
    )
