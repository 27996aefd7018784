"""`ReaderConfig`: how a recording is turned into a `CalibrationProblem` (topics, frames, stops).

Frozen pydantic models with the defaults of the input contract (DESIGN.md); the reader unpacks them
into keyword arguments so the stop detector and decoders never see a config object.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from pipeline.transforms import Matrix4, from_translation_xyzw

_FROZEN = ConfigDict(frozen=True, extra="forbid")


class PoseConfig(BaseModel):
    """An initial `T_base_lidar`, written like `result.json`'s `initial` entries."""

    model_config = _FROZEN

    translation: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @field_validator("rotation_xyzw")
    @classmethod
    def _non_zero(
        cls, value: tuple[float, float, float, float]
    ) -> tuple[float, float, float, float]:
        if sum(v * v for v in value) < 1e-12:
            raise ValueError("rotation_xyzw must be a non-zero quaternion [x, y, z, w]")
        return value

    def matrix(self) -> Matrix4:
        return from_translation_xyzw(self.translation, self.rotation_xyzw)


class StopDetectionConfig(BaseModel):
    """When the robot counts as standing still (speeds from pose differences, not the twist)."""

    model_config = _FROZEN

    max_linear_speed: float = Field(default=0.02, gt=0, description="m/s")
    max_angular_speed_deg: float = Field(default=1.0, gt=0, description="deg/s")
    min_dwell_s: float = Field(
        default=0.3,
        gt=0,
        description="shortest stop kept, seconds (routines stop for 0.3-3 s; a stop under "
        "1 s is kept with a warning, see WarningThresholds.short_stop_s)",
    )
    min_scan_periods: float = Field(
        default=3.0,
        ge=0,
        description="... or this many scan periods of the slowest LiDAR, if longer: a stop that "
        "long holds at least one scan wholly inside it, whatever the scans' phase",
    )
    speed_window_s: float = Field(
        default=0.2,
        ge=0,
        description="speeds are measured over this centred window, which damps jitter",
    )
    max_sample_gap_s: float = Field(
        default=0.5,
        gt=0,
        description="a longer gap in the trajectory ends a stop: nothing is known there",
    )


class ArchiveLimits(BaseModel):
    """What an uploaded `.zip` / `.tar(.gz)` may expand to before we refuse it as absurd."""

    model_config = _FROZEN

    max_extracted_bytes: int = Field(default=32 * 2**30, gt=0)
    max_members: int = Field(default=10_000, gt=0)


class WarningThresholds(BaseModel):
    """When `fleetcal inspect` (and the problem's `recording.warnings`) warn about the data."""

    model_config = _FROZEN

    min_stops: int = Field(
        default=8, ge=1, description="fewer stops constrain the extrinsics poorly"
    )
    min_points_per_stop: int = Field(
        default=2000,
        ge=0,
        description="a LiDAR with fewer valid points per stop sees almost nothing",
    )
    min_relative_points: float = Field(
        default=0.05, ge=0, le=1, description="same, relative to the median LiDAR's points per stop"
    )
    short_stop_s: float = Field(
        default=1.0,
        ge=0,
        description="stops shorter than this are kept, with a warning: the benchmark's routines "
        "all stop at least this long, so shorter ones are outside what it has measured",
    )
    min_scans_per_stop: int = Field(
        default=6,
        ge=0,
        description="a LiDAR with fewer scans wholly inside a stop has a sparse cloud there (a "
        "non-repetitive pattern fills its field of view in over many scans); kept, with a warning. "
        "Issue 13 saw 0.5 s stops (4-5 scans of a rosette) calibrate to 22 mm, 0.8 s stops (7) "
        "to 1-3 mm",
    )


class ReaderConfig(BaseModel):
    """Everything the reader needs besides the file. Defaults follow the input contract."""

    model_config = _FROZEN

    trajectory: Literal["auto", "odometry", "tf"] = "auto"
    """`auto`: the odometry topic when the recording has it, else `/tf`."""
    odometry_topic: str = "/odom"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    lidar_topics: tuple[str, ...] = ()
    """PointCloud2 topics that are LiDARs; empty means every PointCloud2 topic."""
    extrinsics: dict[str, PoseConfig] = Field(default_factory=dict)
    """Initial `T_base_lidar` by LiDAR frame; overrides `/tf_static`."""
    drop_zero_points: bool = True
    """Drop points exactly at the sensor origin, the no-return marker of some drivers (Livox)."""
    clock_tolerance_s: float = Field(default=0.5, gt=0)
    """A LiDAR whose header stamps lag its log times by more than this beyond the trajectory's
    lag is on another clock, and is realigned onto the trajectory's (see `pipeline.io.clocks`);
    within it, the difference is transport latency and the header stamps are kept."""
    stops: StopDetectionConfig = StopDetectionConfig()
    archive: ArchiveLimits = ArchiveLimits()
    warnings: WarningThresholds = WarningThresholds()
    scratch_dir: Path | None = None
    """Where archives are unpacked; the system's temporary directory when unset."""
