"""The API's request and response bodies (separate input and public schemas, as in the
full-stack-fastapi-template). A run's result is `pipeline.result_model.ResultDocument`, the model
`result.json` is written from: the API validates and returns that, with its derived angles."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Annotated

from pydantic import (
    AnyUrl,
    BaseModel,
    ConfigDict,
    Field,
    JsonValue,
    StrictBool,
    StrictFloat,
    UrlConstraints,
    computed_field,
    model_validator,
)

from pipeline import ResultDocument, from_translation_xyzw, rpy_deg
from service.models import DeliveryStatus, EventType, OverrideAction, RunKind, RunStatus, Scope
from service.parameters import PlainText
from service.problem_details import Problem

ROBOT_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"

RobotId = Annotated[str, Field(pattern=ROBOT_ID_PATTERN, examples=["R1"])]
# Numbers in request bodies must be JSON numbers: lax parsing read `true` as 1.0 and "0.5" as 0.5
# (the API fuzzer had a tolerance limit that was no number accepted; `true` became 1 m).
Vector3 = tuple[StrictFloat, StrictFloat, StrictFloat]
Quaternion = tuple[StrictFloat, StrictFloat, StrictFloat, StrictFloat]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class StoredPose(_Strict):
    """`T_base_lidar`: translation in metres, rotation as a unit quaternion [x, y, z, w]."""

    translation: Vector3
    rotation_xyzw: Quaternion


class Pose(StoredPose):
    """`T_base_lidar` as accepted: a quaternion with a direction (the worker normalises it)."""

    @model_validator(mode="after")
    def _rotation_has_a_direction(self) -> Pose:
        # The worker's own rule: a pose it cannot use fails every run that compares against it.
        try:
            from_translation_xyzw(self.translation, self.rotation_xyzw)
        except ValueError as err:
            raise ValueError(f"rotation_xyzw: {err}") from err
        return self


# -- runs ---------------------------------------------------------------------------------------


class UploadInfo(BaseModel):
    size: int = Field(description="Bytes received.")
    sha256: str = Field(description="Hex SHA-256 of the recording.")
    format: str = Field(
        description="Format recognised from the magic bytes.", examples=["mcap", "ros1", "zip"]
    )


class RunSummary(BaseModel):
    """A run as listed: status and verdict, without the result document."""

    id: uuid.UUID
    robot_id: str
    kind: RunKind
    status: RunStatus
    attempts: int
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    passed: bool | None = Field(description="The verdict, once a result exists.")
    metric_error_final: float | None = Field(description="Metres, once a result exists.")
    accepted: bool | None = Field(
        default=None,
        description="Whether the result is in use: its verdict, unless an operator accepted or "
        "rejected it (see `overrides`).",
    )


class OverrideIn(_Strict):
    reason: PlainText = Field(
        min_length=1, max_length=1000, description="Why: kept in the audit trail."
    )


class OverridePublic(BaseModel):
    """An operator's accept or reject of a result: who, when and why."""

    action: OverrideAction
    reason: str
    key_id: str = Field(description="The API key that made it.")
    key_name: str | None
    created_at: datetime


class RunPublic(RunSummary):
    """A run with its progress and, once finished, its `result` or its `error`."""

    max_attempts: int
    stage: str | None = Field(description="The pipeline stage running now.")
    progress: float | None = Field(description="0..1 while running.")
    upload: UploadInfo
    idempotency_key: str | None
    config: dict[str, JsonValue] | None = Field(
        description="The calibration config sent with the upload (X-Fleetcal-Config), if any."
    )
    result: ResultDocument | None = Field(description="The run's result.json document.")
    error: Problem | None = Field(description="Why the run failed (a problem document).")
    overrides: list[OverridePublic] = Field(
        default_factory=list, description="Accepts and rejects of the result, oldest first."
    )


class RunPage(BaseModel):
    items: list[RunSummary]
    next_cursor: str | None = Field(
        description="Pass as `cursor` for the next page; null on the last page."
    )


# -- robots -------------------------------------------------------------------------------------


class RobotUpdate(_Strict):
    """What an admin sets on a robot (PUT replaces both fields)."""

    model: str | None = Field(
        default=None,
        pattern=NAME_PATTERN,
        description="Robot model; selects the tolerance profile.",
    )
    metadata: dict[str, JsonValue] = Field(default_factory=dict)


class RobotPublic(BaseModel):
    id: str
    model: str | None
    metadata: dict[str, JsonValue]
    created_at: datetime
    updated_at: datetime


class RobotDetail(RobotPublic):
    tolerance_profile: str | None = Field(
        description="The profile its verdicts use: the one for its model, else the default profile."
    )
    latest_run: RunSummary | None


class RobotPage(BaseModel):
    items: list[RobotPublic]
    next_cursor: str | None


class LidarCalibration(BaseModel):
    translation: Vector3
    rotation_xyzw: Quaternion
    is_reference: bool
    stddev: dict[str, JsonValue] | None


class CalibrationPublic(BaseModel):
    """A robot's latest accepted (passed) calibration."""

    robot_id: str
    run_id: uuid.UUID
    measured_at: datetime = Field(description="When the recording was uploaded.")
    metric_error_initial: float | None
    metric_error_final: float | None
    pipeline_version: str
    lidars: dict[str, LidarCalibration] = Field(description="`T_base_lidar` per LiDAR frame.")
    result: ResultDocument


class HistoryPoint(BaseModel):
    run_id: uuid.UUID
    frame: str
    measured_at: datetime
    passed: bool
    accepted: bool = Field(description="In use: the verdict unless an operator overrode it.")
    is_reference: bool
    translation: Vector3
    rotation_xyzw: Quaternion
    stddev: dict[str, JsonValue] | None

    @computed_field(description="fixed-axis roll, pitch, yaw in degrees (URDF's rpy)")  # type: ignore[prop-decorator]
    @property
    def rpy_deg(self) -> tuple[float, float, float]:
        return rpy_deg(self.rotation_xyzw)


class HistoryPage(BaseModel):
    """Per-LiDAR extrinsic series, oldest first, for drift plots."""

    robot_id: str
    items: list[HistoryPoint]
    next_cursor: str | None


class ComparedRun(BaseModel):
    run_id: uuid.UUID
    measured_at: datetime
    passed: bool
    accepted: bool


class LidarChange(BaseModel):
    """How one LiDAR's `T_base_lidar` changed from the first run to the second."""

    translation_m: float | None = Field(description="Distance between the two positions.")
    rotation_deg: float | None = Field(description="Angle of the relative rotation.")
    delta_translation: Vector3 | None = Field(
        description="Second translation minus first, in the base frame (m)."
    )
    in_from: bool = Field(description="The first run calibrated this LiDAR.")
    in_to: bool = Field(description="The second run calibrated this LiDAR.")


class RunComparison(BaseModel):
    robot_id: str
    from_run: ComparedRun
    to_run: ComparedRun
    lidars: dict[str, LidarChange]


# -- webhooks -------------------------------------------------------------------------------------


WebhookUrl = Annotated[AnyUrl, UrlConstraints(max_length=2048, allowed_schemes=["http", "https"])]


class WebhookIn(_Strict):
    url: WebhookUrl = Field(description="Where deliveries are POSTed (http or https).")
    events: list[EventType] = Field(min_length=1, description="What to be told about.")
    robot_model: str | None = Field(
        default=None, pattern=NAME_PATTERN, description="Only robots of this model; all if unset."
    )
    secret: str | None = Field(
        default=None,
        min_length=16,
        max_length=128,
        pattern=r"^[\x21-\x7e]+$",
        description="Signing secret; one is made if unset. Shown only in this response.",
    )


class WebhookPublic(BaseModel):
    id: uuid.UUID
    url: str
    events: list[EventType]
    robot_model: str | None
    created_at: datetime


class WebhookCreated(WebhookPublic):
    secret: str = Field(
        description="Verify each delivery's `X-Fleetcal-Signature: sha256=<hex>`, the "
        "HMAC-SHA256 of the body with this secret. Not shown again."
    )


class WebhookPage(BaseModel):
    items: list[WebhookPublic]


class DeliveryPublic(BaseModel):
    """One event sent (or being sent) to one webhook, and the outcome of its last try."""

    id: uuid.UUID
    event_id: uuid.UUID = Field(description="`X-Fleetcal-Event-Id`: drop repeats by it.")
    event: EventType
    run_id: uuid.UUID | None
    robot_id: str
    status: DeliveryStatus
    attempts: int
    max_attempts: int
    available_at: datetime = Field(description="When the next try is due (pending).")
    last_status_code: int | None = Field(description="The receiver's last HTTP status.")
    last_error: str | None
    created_at: datetime
    delivered_at: datetime | None
    payload: dict[str, JsonValue] = Field(description="The body sent.")


class DeliveryPage(BaseModel):
    items: list[DeliveryPublic]
    next_cursor: str | None


# -- tolerance profiles -------------------------------------------------------------------------


class ToleranceLimits(_Strict):
    """Limits a run must meet to pass. Unset, eq. 12, drift and deviation are not checked, and the
    seen metric and the standard deviations keep the pipeline's defaults (20 mm; 5 mm, 0.1 deg)."""

    max_metric_error_m: StrictFloat | None = Field(
        default=None,
        gt=0,
        description="Eq. 12 after calibration (metres). It counts the object parts one LiDAR saw "
        "and the reference did not, so it depends on the routine as much as on the calibration.",
    )
    max_seen_metric_error_m: StrictFloat | None = Field(
        default=None,
        gt=0,
        description="Per LiDAR, the mean distance (metres) of its object points from the "
        "surfaces the reference saw at the same places.",
    )
    max_translation_stddev_m: StrictFloat | None = Field(default=None, gt=0)
    max_rotation_stddev_deg: StrictFloat | None = Field(default=None, gt=0)
    max_translation_drift_m: StrictFloat | None = Field(
        default=None,
        gt=0,
        description="Maintenance runs: change from the last accepted calibration.",
    )
    max_rotation_drift_deg: StrictFloat | None = Field(default=None, gt=0)
    max_translation_deviation_m: StrictFloat | None = Field(
        default=None, gt=0, description="End-of-line runs: difference from the design extrinsics."
    )
    max_rotation_deviation_deg: StrictFloat | None = Field(default=None, gt=0)


_DESIGN_EXTRINSICS = "The model's design `T_base_lidar` per LiDAR frame."


class _ToleranceProfileFields(_Strict):
    robot_model: str | None = Field(
        default=None, pattern=NAME_PATTERN, description="The robot model this profile applies to."
    )
    # Strict: lax parsing took 0 and "no" for booleans.
    is_default: StrictBool = Field(
        default=False,
        description="Used for robots whose model has no "
        "profile; setting it clears the flag on the previous default.",
    )
    limits: ToleranceLimits = Field(default_factory=ToleranceLimits)


class ToleranceProfileIn(_ToleranceProfileFields):
    design_extrinsics: dict[PlainText, Pose] | None = Field(
        default=None, description=_DESIGN_EXTRINSICS
    )


class ToleranceProfilePublic(_ToleranceProfileFields):
    model_config = ConfigDict(extra="ignore")

    # As stored: a profile accepted before poses were checked must still show, to be replaced.
    design_extrinsics: dict[str, StoredPose] | None = Field(
        default=None, description=_DESIGN_EXTRINSICS
    )
    name: str
    created_at: datetime
    updated_at: datetime


class ToleranceProfilePage(BaseModel):
    items: list[ToleranceProfilePublic]


# -- keys ---------------------------------------------------------------------------------------


class KeyPublic(BaseModel):
    """An API key as its holder may see it: never the secret."""

    id: str = Field(description="The key's public id (its first part).")
    name: str | None
    scopes: list[Scope] = Field(description="`admin` implies every other scope.")
    robot_id: str | None = Field(description="The only robot an upload key bound to one serves.")


# -- health -------------------------------------------------------------------------------------


class Health(BaseModel):
    status: str = "ok"


class Readiness(BaseModel):
    status: str
    checks: dict[str, str]
