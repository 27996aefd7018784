"""`CalibrationResult` -> the `result.json` document of DESIGN.md (CLI and API return the same).

Contract fields, never renamed: schema_version, reference_frame, base_frame, lidars{frame: {topic,
initial, calibrated, stddev}}, metric_error{initial, final}, verdict{passed, checks[]},
stages{name: {seconds, ...}}, pipeline_version, config_hash. Added here: per LiDAR
`undetermined`, `object_points`, `change` and `metric_error`; per check `detail` (and `dofs`);
top level `warnings` (the recording's, and config settings naming frames it lacks), `iterations`,
`converged`, `error_per_iteration`, `stops` (refined `T_odom_base`) and `config` (resolved).
A LiDAR with undetermined degrees of freedom gets `"calibrated": null` and null stddev for those
DoF: never a confident number. Non-finite numbers become null (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from pipeline.calibrate import CalibrationResult, LidarCalibration
from pipeline.config import resolved
from pipeline.observability import DOF_NAMES
from pipeline.transforms import Matrix4, to_translation_xyzw
from pipeline.verdict import Check

SCHEMA_VERSION = 1
SCHEMA_FILE = "result_schema.json"


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def pose_document(T: Matrix4) -> dict[str, list[float]]:
    """`{"translation": [x, y, z], "rotation_xyzw": [x, y, z, w]}` of a (4, 4) transform."""
    translation, quaternion = to_translation_xyzw(T)
    return {"translation": translation.tolist(), "rotation_xyzw": quaternion.tolist()}


def _lidar_document(lidar: LidarCalibration) -> dict[str, Any]:
    undetermined = set(lidar.uncertainty.undetermined)
    stddev = np.concatenate(
        [lidar.uncertainty.stddev_translation_m, lidar.uncertainty.stddev_rotation_deg]
    )
    values = [
        None if name in undetermined else _number(value)
        for name, value in zip(DOF_NAMES, stddev, strict=True)
    ]
    translation, rotation = lidar.change
    return {
        "topic": lidar.topic,
        "reference": lidar.is_reference,
        "initial": pose_document(lidar.T_base_lidar_initial),
        "calibrated": None if undetermined else pose_document(lidar.T_base_lidar_calibrated),
        "stddev": {"translation_m": values[:3], "rotation_deg": values[3:]},
        "undetermined": [name for name in DOF_NAMES if name in undetermined],
        "object_points": lidar.object_points,
        "change": {
            "translation_m": None if undetermined else translation,
            "rotation_deg": None if undetermined else rotation,
        },
        "metric_error": {
            "initial": _number(lidar.metric_initial),
            "final": _number(lidar.metric_final),
        },
    }


def _check_document(check: Check) -> dict[str, Any]:
    document: dict[str, Any] = {
        "name": check.name,
        "value": _number(check.value),
        "limit": _number(check.limit),
        "passed": check.passed,
    }
    if check.detail:
        document["detail"] = check.detail
    if check.dofs:
        document["dofs"] = list(check.dofs)
    return document


def result_document(
    result: CalibrationResult, *, read_seconds: float | None = None
) -> dict[str, Any]:
    """The `result.json` document (plain JSON data) of a calibration; `read_seconds` (the time
    the reader took, when the caller read a file) becomes the stage `read`."""
    stages: dict[str, dict[str, Any]] = {}
    if read_seconds is not None:
        stages["read"] = {"seconds": read_seconds}
    stages |= {
        name: {
            "seconds": report.seconds,
            **{
                key: _number(value) if isinstance(value, float) else value
                for key, value in report.details.items()
            },
        }
        for name, report in result.stages.items()
    }
    return {
        "schema_version": SCHEMA_VERSION,
        "reference_frame": result.reference_frame,
        "base_frame": result.base_frame,
        "lidars": {lidar.frame: _lidar_document(lidar) for lidar in result.lidars},
        "metric_error": {
            "initial": _number(result.metric_error_initial),
            "final": _number(result.metric_error_final),
        },
        "verdict": {
            "passed": result.verdict.passed,
            "checks": [_check_document(check) for check in result.verdict.checks],
        },
        "stages": stages,
        "pipeline_version": result.pipeline_version,
        "config_hash": result.config_hash,
        "warnings": list(result.warnings),
        "iterations": result.iterations,
        "converged": result.converged,
        "error_per_iteration": [_number(e) for e in result.error_per_iteration],
        "stops": [
            {"index": index, "T_odom_base": pose_document(T)}
            for index, T in enumerate(result.T_odom_base)
        ],
        "config": resolved(result.config),
    }


def dumps(result: CalibrationResult, *, read_seconds: float | None = None) -> str:
    """`result.json`'s text: indented, keys in contract order, no NaN."""
    document = result_document(result, read_seconds=read_seconds)
    return json.dumps(document, indent=2, allow_nan=False) + "\n"


@cache
def result_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) every `result.json` satisfies."""
    text = resources.files("pipeline").joinpath(SCHEMA_FILE).read_text(encoding="utf-8")
    schema: dict[str, Any] = json.loads(text)
    return schema
