"""`result.json` as one typed model: what `fleetcal calibrate` writes, what the service validates,
stores and returns, and the source its JSON Schema (`result_schema.json`) is generated from.

Contract fields, never renamed: schema_version, reference_frame, base_frame, lidars{frame: {topic,
initial, calibrated, stddev}}, metric_error{initial, final}, verdict{passed, checks[]},
stages{name: {seconds, ...}}, pipeline_version, config_hash. Added since: per LiDAR `reference`,
`undetermined`, `object_points`, `change` and `metric_error`; per check `detail` (and `dofs`); top
level `warnings`, `iterations`, `converged`, `error_per_iteration`, `stops` and `config`. The
worker adds `tolerance_profile`, `drift` (the comparison its drift checks judged) and `report`.
Fields may be added in later versions, so every part keeps the members it does not know; the ones
older documents lack have defaults. Non-finite numbers are null (JSON has no NaN).

Derived values are computed fields (`rpy_deg` of every pose): the API returns them, so no client
re-derives them, and `result.json` (`result_document` dumps without them) stays the contract.

Regenerate the schema after a change with `python -m pipeline.result_model` (`--check` compares).
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any, Final, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    JsonValue,
    computed_field,
    field_validator,
)
from scipy.spatial.transform import Rotation

from pipeline.transforms import from_translation_xyzw

SCHEMA_VERSION: Final = 1
SCHEMA_FILE = Path(__file__).with_name("result_schema.json")
_SCHEMA_HEADER = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "https://fleetcal.invalid/schemas/result-v1.json",
    "title": "fleetcal result.json, schema version 1",
}

NonNegative = Annotated[float, Field(ge=0)]
Vector3 = tuple[float, float, float]
Vector3OrNull = tuple[NonNegative | None, NonNegative | None, NonNegative | None]
UnitComponent = Annotated[float, Field(ge=-1, le=1)]
Quaternion = tuple[UnitComponent, UnitComponent, UnitComponent, UnitComponent]
Dof = Literal["x", "y", "z", "roll", "pitch", "yaw"]
"""The six degrees of freedom, in `pipeline.observability.DOF_NAMES` order."""


def _is_none(value: object) -> bool:
    return value is None


def _is_empty(value: object) -> bool:
    return not value


class _Part(BaseModel):
    """A part of the document: frozen, no NaN, members of later versions kept as they are."""

    model_config = ConfigDict(extra="allow", allow_inf_nan=False, frozen=True)


def rpy_deg(rotation_xyzw: Quaternion) -> tuple[float, float, float]:
    """Fixed-axis roll, pitch, yaw in degrees (x, then y, then z: URDF's `rpy`) of a quaternion."""
    roll, pitch, yaw = Rotation.from_quat(np.asarray(rotation_xyzw, float)).as_euler(
        "xyz", degrees=True
    )
    return float(roll), float(pitch), float(yaw)


class PoseResult(_Part):
    """`T_parent_child` (`T_base_lidar`, `T_odom_base`): metres and a unit quaternion."""

    translation: Vector3
    rotation_xyzw: Quaternion = Field(description="unit quaternion [x, y, z, w]")

    @field_validator("rotation_xyzw")
    @classmethod
    def _has_a_direction(cls, value: Quaternion) -> Quaternion:
        # The service compares later runs with this pose (drift): it must be a rotation.
        from_translation_xyzw((0.0, 0.0, 0.0), value)
        return value

    @computed_field(description="fixed-axis roll, pitch, yaw in degrees (URDF's rpy)")  # type: ignore[prop-decorator]
    @property
    def rpy_deg(self) -> tuple[float, float, float]:
        return rpy_deg(self.rotation_xyzw)


class Stddev(_Part):
    """1-sigma per axis; null for a degree of freedom the data do not determine."""

    translation_m: Vector3OrNull
    rotation_deg: Vector3OrNull


class PoseChange(_Part):
    """Translation (m) and rotation angle (deg) between two poses."""

    translation_m: NonNegative | None
    rotation_deg: NonNegative | None


class MetricError(_Part):
    """Eq. 12 (metres) with the initial and the calibrated extrinsics; null when not measured."""

    initial: NonNegative | None
    final: NonNegative | None


class LidarResult(_Part):
    topic: str
    reference: bool = Field(default=False, description="the reference LiDAR (fixed)")
    initial: PoseResult
    calibrated: PoseResult | None = Field(
        description="null when the data do not determine this LiDAR (see undetermined)"
    )
    stddev: Stddev
    undetermined: tuple[Dof, ...] = Field(default=(), json_schema_extra={"uniqueItems": True})
    object_points: int | None = Field(default=None, ge=0)
    change: PoseChange | None = Field(
        default=None, description="from the initial to the calibrated pose; null when undetermined"
    )
    metric_error: MetricError | None = None


class CheckResult(_Part):
    """One check of the verdict (`pipeline.verdict.Check`); `detail` says what failed."""

    name: str = Field(min_length=1)
    value: float | None
    limit: float | None
    passed: bool
    detail: str = Field(default="", exclude_if=_is_empty)
    dofs: tuple[Dof, ...] = Field(default=(), exclude_if=_is_empty)


class VerdictResult(_Part):
    passed: bool
    checks: list[CheckResult] = Field(min_length=1)


class StageTiming(_Part):
    """A stage's wall time and what it did (plain numbers, flags and words)."""

    __pydantic_extra__: dict[str, JsonValue] = Field(init=False)

    seconds: NonNegative


class Stop(_Part):
    index: int = Field(ge=0)
    T_odom_base: PoseResult


class DriftResult(_Part):
    """The calibrated poses against reference poses: the evidence of the verdict's drift checks."""

    against: Literal["last_accepted", "design"]
    lidars: dict[str, PoseChange] = Field(description="per calibrated LiDAR the reference knows")
    missing: list[str] = Field(description="LiDARs the reference knows that were not calibrated")
    run_id: str | None = Field(
        default=None, exclude_if=_is_none, description="the run the reference poses are from"
    )
    measured_at: datetime | None = Field(default=None, exclude_if=_is_none)


class ReportImages(_Part):
    images: list[str] = Field(description="names of the stored report images")
    error: str | None = Field(default=None, exclude_if=_is_none)


class ResultDocument(_Part):
    """The outcome of one calibration. Transforms are T_base_lidar: translation in metres and a
    unit quaternion [x, y, z, w]. Fields may be added in later versions; none is renamed."""

    schema_version: Literal[1]
    reference_frame: str = Field(min_length=1)
    base_frame: str = Field(min_length=1)
    lidars: dict[str, LidarResult] = Field(min_length=2)
    metric_error: MetricError
    verdict: VerdictResult
    stages: dict[str, StageTiming]
    pipeline_version: str = Field(min_length=1, max_length=64)
    config_hash: str = Field(pattern=r"^sha256:[0-9a-f]{64}$")
    warnings: list[str] = Field(default_factory=list)
    iterations: int | None = Field(default=None, ge=0)
    converged: bool | None = None
    error_per_iteration: list[NonNegative | None] = Field(default_factory=list)
    stops: list[Stop] = Field(default_factory=list)
    config: dict[str, JsonValue] = Field(
        default_factory=dict, description="the resolved PipelineConfig"
    )
    tolerance_profile: str | None = Field(default=None, exclude_if=_is_none)
    drift: DriftResult | None = Field(default=None, exclude_if=_is_none)
    report: ReportImages | None = Field(default=None, exclude_if=_is_none)


def result_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of `result.json`, generated from `ResultDocument`."""
    schema = ResultDocument.model_json_schema(mode="validation")
    return {**_SCHEMA_HEADER, **schema, "title": _SCHEMA_HEADER["title"]}


def schema_text() -> str:
    """`result_schema.json`'s text: what `python -m pipeline.result_model` writes."""
    return json.dumps(result_schema(), indent=2, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m pipeline.result_model",
        description=f"Write {SCHEMA_FILE.name}, generated from ResultDocument.",
    )
    parser.add_argument(
        "--check", action="store_true", help="exit 1 if the file differs, write nothing"
    )
    args = parser.parse_args(argv)
    text = schema_text()
    current = SCHEMA_FILE.read_text(encoding="utf-8") if SCHEMA_FILE.exists() else ""
    if args.check:
        if current != text:
            print(
                f"{SCHEMA_FILE} is out of date: run python -m pipeline.result_model",
                file=sys.stderr,
            )
            return 1
        return 0
    SCHEMA_FILE.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
