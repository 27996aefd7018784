"""The verdict: checks of a calibration against tolerances, each with its value, limit and outcome.

Tolerances live in `VerdictConfig`; the service passes a robot model's tolerance profile as one.
Evidence the pipeline cannot know (the robot's last accepted calibration: drift) is judged by the
same checks (`with_drift`), so a verdict is only ever made here, never edited after.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class VerdictConfig(BaseModel):
    """Limits; a `None` limit skips its check."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    max_metric_error_m: float | None = Field(
        default=None,
        gt=0,
        description="eq. 12 after calibration, when set. It counts the parts of objects one LiDAR "
        "saw and the reference did not at the cap (6-72 mm with the extrinsics within 5 mm over "
        "bench_random's recordings), so it judges the routine's coverage as much as the "
        "calibration; max_seen_metric_error_m judges the calibration. None: not checked",
    )
    max_seen_metric_error_m: float | None = Field(
        default=0.02,
        gt=0,
        description="per LiDAR, the mean distance of its object points the reference's rays "
        "reached from the reference's surfaces there, along their normals (pipeline.visibility): "
        "a misplaced LiDAR's points lie off those surfaces or in front of them. None: not checked",
    )
    min_seen_points: int = Field(
        default=100,
        ge=1,
        description="a LiDAR with fewer object points the reference saw fails "
        "max_seen_metric_error_m's check: nothing confirms where it placed its objects",
    )
    max_translation_stddev_m: float = Field(default=0.005, gt=0, description="per axis, per LiDAR")
    max_rotation_stddev_deg: float = Field(default=0.1, gt=0, description="per axis, per LiDAR")
    min_object_points: int = Field(
        default=200, ge=0, description="object points per LiDAR over all stops, after voxelisation"
    )
    require_convergence: bool = True
    max_deviation_translation_m: float | None = Field(
        default=None, gt=0, description="largest accepted change from the initial T_base_lidar"
    )
    max_deviation_rotation_deg: float | None = Field(default=None, gt=0)
    min_start_separation_sigmas: float | None = Field(
        default=3.0,
        gt=0,
        description="where stage 4 ran from two starts and they ended further apart than "
        "starts_apart_translation_m or starts_apart_rotation_deg, the kept solution must place "
        "the points nearer the reference's map by this many standard errors (a jackknife over "
        "blocks of space), else the recording fits two calibrations alike and the verdict fails "
        "as ambiguous (bench_random seed 1066: starts 1.5 and 2.1 m off the truth, 0.9 "
        "standard errors apart; seed 1001: the kept start right, the other 1.2 m off and 3.2 "
        "standard errors worse). None skips the check",
    )
    starts_apart_translation_m: float = Field(
        default=0.01, gt=0, description="two solutions this far apart are two calibrations"
    )
    starts_apart_rotation_deg: float = Field(default=0.3, gt=0)


@dataclass(frozen=True)
class Check:
    """One check. `detail` says what failed in words; `dofs` names undetermined DoF."""

    name: str
    value: float
    limit: float
    passed: bool
    detail: str = ""
    dofs: tuple[str, ...] = ()


@dataclass(frozen=True)
class LidarEvidence:
    """What the verdict needs to know of one LiDAR. `seen_metric_error_m`: the mean distance of
    its object points the reference saw from the reference's surfaces there, `seen_points` how
    many those were (`pipeline.visibility`)."""

    frame: str
    is_reference: bool
    object_points: int
    stddev_translation_m: tuple[float, float, float]
    stddev_rotation_deg: tuple[float, float, float]
    undetermined: tuple[str, ...]
    deviation_translation_m: float
    deviation_rotation_deg: float
    seen_metric_error_m: float = math.nan
    seen_points: int = 0


@dataclass(frozen=True)
class DriftEvidence:
    """The calibrated poses against reference poses, measured after the calibration (the service
    knows the robot's last accepted calibration, or its model's design), with the profile's limits.

    `lidars`: per LiDAR the reference knows and the run calibrated, translation (m) and rotation
    (deg) from the reference pose. `missing`: the LiDARs it knows that the run did not calibrate;
    each fails a check when a limit is set (the robot no longer matches). `run_id` and
    `measured_at` say which calibration the reference is (reported, not judged).
    """

    against: Literal["last_accepted", "design"]
    lidars: Mapping[str, tuple[float, float]]
    missing: tuple[str, ...] = ()
    max_translation_m: float | None = None
    max_rotation_deg: float | None = None
    run_id: str | None = None
    measured_at: datetime | None = None

    @property
    def limited(self) -> bool:
        return self.max_translation_m is not None or self.max_rotation_deg is not None


@dataclass(frozen=True)
class StartsEvidence:
    """Stage 4's two solutions, where global alignment gave it a second start: how far apart they
    ended (the largest over the non-reference LiDARs) and how much nearer the reference's map the
    kept one places the points, in standard errors of that difference."""

    apart_translation_m: float
    apart_rotation_deg: float
    separation_sigmas: float


@dataclass(frozen=True)
class Evidence:
    """Everything a verdict is judged on. It stays with the verdict so that evidence found later
    (drift, in the worker) is judged with the rest (`with_drift`), never added to a verdict."""

    metric_error_m: float
    converged: bool
    iterations: int
    max_iterations: int
    lidars: tuple[LidarEvidence, ...]
    drift: DriftEvidence | None = None
    starts: StartsEvidence | None = None


@dataclass(frozen=True)
class Verdict:
    passed: bool
    checks: tuple[Check, ...]
    evidence: Evidence | None = field(default=None, compare=False, repr=False)
    config: VerdictConfig | None = field(default=None, compare=False, repr=False)

    @property
    def failed(self) -> tuple[Check, ...]:
        return tuple(check for check in self.checks if not check.passed)


def judge(
    metric_error_m: float,
    converged: bool,
    iterations: int,
    max_iterations: int,
    lidars: Sequence[LidarEvidence],
    config: VerdictConfig,
    *,
    drift: DriftEvidence | None = None,
    starts: StartsEvidence | None = None,
) -> Verdict:
    """Run every check; the verdict passes when all of them pass."""
    evidence = Evidence(
        metric_error_m, converged, iterations, max_iterations, tuple(lidars), drift, starts
    )
    return judge_evidence(evidence, config)


def judge_evidence(evidence: Evidence, config: VerdictConfig) -> Verdict:
    """`judge` on an `Evidence` record: the run's checks, each LiDAR's, then the drift checks."""
    checks = [
        *_run_checks(evidence, config),
        *(check for lidar in evidence.lidars for check in _lidar_checks(lidar, config)),
        *(_drift_checks(evidence.drift) if evidence.drift is not None else ()),
    ]
    return Verdict(all(check.passed for check in checks), tuple(checks), evidence, config)


def with_drift(verdict: Verdict, drift: DriftEvidence) -> Verdict:
    """`verdict` judged again on its evidence and `drift`: the same checks, then drift's."""
    if verdict.evidence is None or verdict.config is None:
        raise ValueError("the verdict keeps no evidence (it was not made by judge): judge it anew")
    return judge_evidence(replace(verdict.evidence, drift=drift), verdict.config)


def _at_most(name: str, value: float, limit: float, detail: str) -> Check:
    passed = math.isfinite(value) and value <= limit
    return Check(name, value, limit, passed, "" if passed else detail)


def _run_checks(evidence: Evidence, config: VerdictConfig) -> list[Check]:
    error, limit = evidence.metric_error_m, config.max_metric_error_m
    checks = []
    if limit is not None:
        checks.append(
            _at_most(
                "metric_error",
                error,
                limit,
                f"the maps disagree by {error:.4f} m on average (limit {limit} m)",
            )
        )
    if config.require_convergence:
        converged, limit = evidence.converged, evidence.max_iterations
        checks.append(
            Check(
                "convergence",
                float(evidence.iterations),
                float(limit),
                converged,
                "" if converged else f"no convergence within {limit} iterations",
            )
        )
    if evidence.starts is not None and config.min_start_separation_sigmas is not None:
        checks.append(_unique_solution(evidence.starts, config, config.min_start_separation_sigmas))
    return checks


def fits_alike(starts: StartsEvidence, config: VerdictConfig) -> bool:
    """Whether the recording fits stage 4's two solutions alike: they ended apart (beyond
    `starts_apart_translation_m` or `starts_apart_rotation_deg`) and the maps prefer the kept one
    by fewer than `min_start_separation_sigmas` standard errors (False where that is None)."""
    needed = config.min_start_separation_sigmas
    if needed is None:
        return False
    apart = (
        starts.apart_translation_m > config.starts_apart_translation_m
        or starts.apart_rotation_deg > config.starts_apart_rotation_deg
    )
    return apart and not starts.separation_sigmas >= needed


def _unique_solution(starts: StartsEvidence, config: VerdictConfig, needed: float) -> Check:
    """Whether the kept one of stage 4's two solutions is the only calibration the data support:
    the two ended as one, or the maps prefer the kept one by `needed` standard errors."""
    sigmas = starts.separation_sigmas
    passed = not fits_alike(starts, config)
    detail = (
        ""
        if passed
        else f"the recording fits two calibrations {starts.apart_translation_m:.3f} m / "
        f"{starts.apart_rotation_deg:.2f} deg apart almost alike (the kept one lies nearer the "
        f"reference's map by {sigmas:.1f} standard errors, {needed:g} needed; the reported "
        "1-sigma spans both): record again "
        "with objects that tell them apart (fewer look-alike objects, more turning) or from "
        "an initial guess nearer the truth"
    )
    return Check("unique_solution", sigmas, needed, passed, detail)


def _lidar_checks(lidar: LidarEvidence, config: VerdictConfig) -> list[Check]:
    enough = lidar.object_points >= config.min_object_points
    checks = [
        Check(
            f"object_points:{lidar.frame}",
            float(lidar.object_points),
            float(config.min_object_points),
            enough,
            ""
            if enough
            else f"{lidar.frame} saw too few object points; place objects "
            "(about 0.25 m tall) in its view during the stops",
        )
    ]
    if lidar.is_reference:
        return checks
    missing = lidar.undetermined
    checks.append(
        Check(
            f"determined:{lidar.frame}",
            float(len(missing)),
            0.0,
            not missing,
            f"the data do not determine {', '.join(missing)} of {lidar.frame}" if missing else "",
            missing,
        )
    )
    return [
        *checks,
        *_seen_metric_checks(lidar, config),
        *_uncertainty_checks(lidar, config),
        *_deviation_checks(lidar, config),
    ]


def _seen_metric_checks(lidar: LidarEvidence, config: VerdictConfig) -> list[Check]:
    """The LiDAR's seen metric (its points the reference saw, against the reference's surfaces)
    where the config limits it; failed, saying so, where the reference saw too few to tell."""
    limit = config.max_seen_metric_error_m
    if limit is None:
        return []
    name, error = f"seen_metric_error:{lidar.frame}", lidar.seen_metric_error_m
    if lidar.seen_points < config.min_seen_points:
        return [
            Check(
                name,
                math.nan,
                limit,
                False,
                f"the reference saw {lidar.seen_points} of {lidar.frame}'s object points "
                f"({config.min_seen_points} needed), so nothing confirms where the calibration "
                f"placed them: record turning further, so that the reference sees the objects "
                f"{lidar.frame} sees",
            )
        ]
    return [
        _at_most(
            name,
            error,
            limit,
            f"{lidar.frame}'s object points lie {error:.4f} m on average from what the reference "
            f"saw of the same places (limit {limit} m): the calibration is off or the scene "
            "moved between their stops",
        )
    ]


def _uncertainty_checks(lidar: LidarEvidence, config: VerdictConfig) -> list[Check]:
    translation, rotation = max(lidar.stddev_translation_m), max(lidar.stddev_rotation_deg)
    return [
        _at_most(
            f"uncertainty_translation:{lidar.frame}",
            translation,
            config.max_translation_stddev_m,
            f"{lidar.frame}'s position is uncertain by up to {translation:.4f} m (1 sigma)",
        ),
        _at_most(
            f"uncertainty_rotation:{lidar.frame}",
            rotation,
            config.max_rotation_stddev_deg,
            f"{lidar.frame}'s orientation is uncertain by up to {rotation:.3f} deg (1 sigma)",
        ),
    ]


def _deviation_checks(lidar: LidarEvidence, config: VerdictConfig) -> list[Check]:
    """The change from the initial extrinsics, where the config limits it."""
    checks = []
    if config.max_deviation_translation_m is not None:
        checks.append(
            _at_most(
                f"deviation_translation:{lidar.frame}",
                lidar.deviation_translation_m,
                config.max_deviation_translation_m,
                f"{lidar.frame} moved {lidar.deviation_translation_m:.3f} m from its initial pose",
            )
        )
    if config.max_deviation_rotation_deg is not None:
        checks.append(
            _at_most(
                f"deviation_rotation:{lidar.frame}",
                lidar.deviation_rotation_deg,
                config.max_deviation_rotation_deg,
                f"{lidar.frame} turned {lidar.deviation_rotation_deg:.2f} deg from its "
                "initial pose",
            )
        )
    return checks


# Check names are `<what>:<frame>`; "deviation" above already means the change from the initial
# extrinsics, hence "design" for the comparison with the design. The service's webhooks select
# `drift_*` checks (`service.outbox`).
_DRIFT_KIND = {"last_accepted": "drift", "design": "design"}
_DRIFT_QUESTION = {
    "drift": "last accepted calibration (limit {limit} {unit}): has its mount moved or been hit?",
    "design": "design pose (limit {limit} {unit}): is it mounted as the model says?",
}


def _drift_checks(drift: DriftEvidence) -> list[Check]:
    """Per LiDAR the reference knows, in frame order: its translation and rotation from the
    reference pose against each limit set, or, when it was not calibrated, a failed check."""
    kind = _DRIFT_KIND[drift.against]
    checks = []
    for frame in sorted({*drift.lidars, *drift.missing}):
        if frame not in drift.lidars:
            if drift.limited:
                reference = drift.against.replace("_", " ")
                checks.append(
                    Check(
                        f"{kind}_missing:{frame}",
                        math.nan,
                        math.nan,
                        False,
                        f"{frame} is in the {reference} extrinsics but was not calibrated",
                    )
                )
            continue
        distance_m, angle_deg = drift.lidars[frame]
        for name, value, limit, unit in (
            (f"{kind}_translation:{frame}", distance_m, drift.max_translation_m, "m"),
            (f"{kind}_rotation:{frame}", angle_deg, drift.max_rotation_deg, "deg"),
        ):
            if limit is None:
                continue
            passed = value <= limit
            question = _DRIFT_QUESTION[kind].format(limit=limit, unit=unit)
            detail = "" if passed else f"{frame} is {value:.4g} {unit} away from its {question}"
            checks.append(Check(name, value, limit, passed, detail))
    return checks
