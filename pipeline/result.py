"""`CalibrationResult` -> the `result.json` document (`pipeline.result_model`; CLI and API return
the same). A LiDAR with undetermined degrees of freedom gets `"calibrated": null` and null stddev
for those DoF: never a confident number. Non-finite numbers become null (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from typing import Any, cast

import numpy as np

from pipeline.calibrate import CalibrationResult, LidarCalibration
from pipeline.config import resolved
from pipeline.observability import DOF_NAMES
from pipeline.result_model import (
    SCHEMA_VERSION,
    CheckResult,
    Dof,
    DriftResult,
    LidarResult,
    MetricError,
    PoseChange,
    PoseResult,
    ResultDocument,
    StageTiming,
    Stddev,
    Stop,
    VerdictResult,
    result_schema,
)
from pipeline.transforms import Matrix4, to_translation_xyzw
from pipeline.verdict import Check, DriftEvidence, Verdict

__all__ = [
    "SCHEMA_VERSION",
    "dumps",
    "pose_document",
    "result_document",
    "result_model",
    "result_schema",
]


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _triple(values: list[float | None]) -> tuple[float | None, float | None, float | None]:
    first, second, third = values
    return first, second, third


def _dofs(names: Iterable[str]) -> tuple[Dof, ...]:
    # `DOF_NAMES` are `Dof`'s values (a test holds them equal); the model checks each at runtime.
    return cast("tuple[Dof, ...]", tuple(names))


def _pose(T: Matrix4) -> PoseResult:
    translation, quaternion = to_translation_xyzw(T)
    return PoseResult(translation=translation.tolist(), rotation_xyzw=quaternion.tolist())


def pose_document(T: Matrix4) -> dict[str, list[float]]:
    """`{"translation": [x, y, z], "rotation_xyzw": [x, y, z, w]}` of a (4, 4) transform."""
    translation, quaternion = to_translation_xyzw(T)
    return {"translation": translation.tolist(), "rotation_xyzw": quaternion.tolist()}


def _lidar(lidar: LidarCalibration) -> LidarResult:
    undetermined = set(lidar.uncertainty.undetermined)
    stddev = np.concatenate(
        [lidar.uncertainty.stddev_translation_m, lidar.uncertainty.stddev_rotation_deg]
    )
    values = [
        None if name in undetermined else _number(value)
        for name, value in zip(DOF_NAMES, stddev, strict=True)
    ]
    translation, rotation = lidar.change
    return LidarResult(
        topic=lidar.topic,
        reference=lidar.is_reference,
        initial=_pose(lidar.T_base_lidar_initial),
        calibrated=None if undetermined else _pose(lidar.T_base_lidar_calibrated),
        stddev=Stddev(translation_m=_triple(values[:3]), rotation_deg=_triple(values[3:])),
        undetermined=_dofs(name for name in DOF_NAMES if name in undetermined),
        object_points=lidar.object_points,
        change=PoseChange(
            translation_m=None if undetermined else translation,
            rotation_deg=None if undetermined else rotation,
        ),
        metric_error=MetricError(
            initial=_number(lidar.metric_initial), final=_number(lidar.metric_final)
        ),
    )


def _check(check: Check) -> CheckResult:
    return CheckResult(
        name=check.name,
        value=_number(check.value),
        limit=_number(check.limit),
        passed=check.passed,
        detail=check.detail,
        dofs=_dofs(check.dofs),
    )


def _verdict(verdict: Verdict) -> VerdictResult:
    return VerdictResult(passed=verdict.passed, checks=[_check(check) for check in verdict.checks])


def _drift(verdict: Verdict) -> DriftResult | None:
    drift: DriftEvidence | None = verdict.evidence.drift if verdict.evidence else None
    if drift is None:
        return None
    return DriftResult(
        against=drift.against,
        lidars={
            frame: PoseChange(translation_m=translation, rotation_deg=rotation)
            for frame, (translation, rotation) in drift.lidars.items()
        },
        missing=list(drift.missing),
        run_id=drift.run_id,
        measured_at=drift.measured_at,
    )


def _stages(result: CalibrationResult, read_seconds: float | None) -> dict[str, StageTiming]:
    stages: dict[str, StageTiming] = {}
    if read_seconds is not None:
        stages["read"] = StageTiming(seconds=read_seconds)
    for name, report in result.stages.items():
        details = {
            key: _number(value) if isinstance(value, float) else value
            for key, value in report.details.items()
        }
        stages[name] = StageTiming(seconds=report.seconds, **details)
    return stages


def result_model(result: CalibrationResult, *, read_seconds: float | None = None) -> ResultDocument:
    """The `result.json` document of a calibration; `read_seconds` (the time the reader took, when
    the caller read a file) becomes the stage `read`. A verdict judged with drift
    (`pipeline.verdict.with_drift`) brings its `drift` section."""
    return ResultDocument(
        schema_version=SCHEMA_VERSION,
        reference_frame=result.reference_frame,
        base_frame=result.base_frame,
        lidars={lidar.frame: _lidar(lidar) for lidar in result.lidars},
        metric_error=MetricError(
            initial=_number(result.metric_error_initial),
            final=_number(result.metric_error_final),
        ),
        verdict=_verdict(result.verdict),
        stages=_stages(result, read_seconds),
        pipeline_version=result.pipeline_version,
        config_hash=result.config_hash,
        warnings=list(result.warnings),
        iterations=result.iterations,
        converged=result.converged,
        error_per_iteration=[_number(e) for e in result.error_per_iteration],
        stops=[
            Stop(index=index, T_odom_base=_pose(T)) for index, T in enumerate(result.T_odom_base)
        ],
        config=resolved(result.config),
        drift=_drift(result.verdict),
    )


def result_document(
    result: CalibrationResult, *, read_seconds: float | None = None
) -> dict[str, Any]:
    """`result_model` as plain JSON data, as `result.json` holds it (no computed fields)."""
    document: dict[str, Any] = result_model(result, read_seconds=read_seconds).model_dump(
        mode="json", exclude_computed_fields=True
    )
    return document


def dumps(result: CalibrationResult, *, read_seconds: float | None = None) -> str:
    """`result.json`'s text: indented, keys in contract order, no NaN."""
    document = result_document(result, read_seconds=read_seconds)
    return json.dumps(document, indent=2, allow_nan=False) + "\n"
