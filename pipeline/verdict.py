"""The verdict: checks of a calibration against tolerances, each with its value, limit and outcome.

Tolerances live in `VerdictConfig`; the service passes a robot model's tolerance profile as one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field


class VerdictConfig(BaseModel):
    """Limits; a `None` limit skips its check."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    max_metric_error_m: float = Field(
        default=0.04,
        gt=0,
        description="eq. 12 after calibration. It includes the point spacing and the parts of "
        "objects one LiDAR saw and the reference did not (~6 mm on set 1, ~30 mm on the driven "
        "loop with the true extrinsics), so it catches gross misalignment; the stddev checks "
        "judge precision",
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
class Verdict:
    passed: bool
    checks: tuple[Check, ...]

    @property
    def failed(self) -> tuple[Check, ...]:
        return tuple(check for check in self.checks if not check.passed)


@dataclass(frozen=True)
class LidarEvidence:
    """What the verdict needs to know of one LiDAR."""

    frame: str
    is_reference: bool
    object_points: int
    stddev_translation_m: tuple[float, float, float]
    stddev_rotation_deg: tuple[float, float, float]
    undetermined: tuple[str, ...]
    deviation_translation_m: float
    deviation_rotation_deg: float


def _at_most(name: str, value: float, limit: float, detail: str) -> Check:
    passed = math.isfinite(value) and value <= limit
    return Check(name, value, limit, passed, "" if passed else detail)


def judge(
    metric_error_m: float,
    converged: bool,
    iterations: int,
    max_iterations: int,
    lidars: Sequence[LidarEvidence],
    config: VerdictConfig,
) -> Verdict:
    """Run every check; the verdict passes when all of them pass."""
    checks = [
        _at_most(
            "metric_error",
            metric_error_m,
            config.max_metric_error_m,
            f"the maps disagree by {metric_error_m:.4f} m on average "
            f"(limit {config.max_metric_error_m} m)",
        )
    ]
    if config.require_convergence:
        checks.append(
            Check(
                "convergence",
                float(iterations),
                float(max_iterations),
                converged,
                "" if converged else f"no convergence within {max_iterations} iterations",
            )
        )
    for lidar in lidars:
        enough = lidar.object_points >= config.min_object_points
        checks.append(
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
        )
        if lidar.is_reference:
            continue
        missing = lidar.undetermined
        checks.append(
            Check(
                f"determined:{lidar.frame}",
                float(len(missing)),
                0.0,
                not missing,
                f"the data do not determine {', '.join(missing)} of {lidar.frame}"
                if missing
                else "",
                missing,
            )
        )
        checks.append(
            _at_most(
                f"uncertainty_translation:{lidar.frame}",
                max(lidar.stddev_translation_m),
                config.max_translation_stddev_m,
                f"{lidar.frame}'s position is uncertain by up to "
                f"{max(lidar.stddev_translation_m):.4f} m (1 sigma)",
            )
        )
        checks.append(
            _at_most(
                f"uncertainty_rotation:{lidar.frame}",
                max(lidar.stddev_rotation_deg),
                config.max_rotation_stddev_deg,
                f"{lidar.frame}'s orientation is uncertain by up to "
                f"{max(lidar.stddev_rotation_deg):.3f} deg (1 sigma)",
            )
        )
        if config.max_deviation_translation_m is not None:
            checks.append(
                _at_most(
                    f"deviation_translation:{lidar.frame}",
                    lidar.deviation_translation_m,
                    config.max_deviation_translation_m,
                    f"{lidar.frame} moved {lidar.deviation_translation_m:.3f} m from its "
                    "initial pose",
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
    return Verdict(passed=all(check.passed for check in checks), checks=tuple(checks))
