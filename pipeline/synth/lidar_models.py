"""LiDAR scan models: when a sensor fires and in which directions, in its own frame.

Directions are unit vectors in the LiDAR frame (x forward along the optical axis for the Mid-70).
Times are seconds on the sensor's clock since the recording started, so the pattern continues
from one scan to the next (a non-repetitive pattern must not restart at every message).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline.problem import ScanPattern

_FROZEN = ConfigDict(frozen=True, extra="forbid")
# Firing instants sit on a global grid k / rate; this slack keeps t0 * rate = 29999.999999 from
# being rounded to the next firing (scan starts are multiples of 0.1 s, not exact in binary).
_GRID_SLACK = 1e-6


@dataclass(frozen=True)
class Firing:
    """Rays of one time span: `times` (N,) seconds, `directions` (N, 3) unit vectors, float64."""

    times: NDArray[np.float64]
    directions: NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.times)


def _grid_times(t0: float, duration: float, rate: float) -> NDArray[np.float64]:
    """Instants `k / rate` in `[t0, t0 + duration)`: consecutive spans never share a firing."""
    first = math.ceil(t0 * rate - _GRID_SLACK)
    end = math.ceil((t0 + duration) * rate - _GRID_SLACK)
    return np.arange(first, end, dtype=np.float64) / rate


class Mid70(BaseModel):
    """Livox Mid-70: circular field of view round +x, non-repetitive rosette from two Risley prisms.

    Each prism deflects the beam by a fixed angle in the direction it currently faces; the two
    rotate in opposite senses at incommensurate speeds, so the sum of the two deflections traces
    a rosette whose petals never repeat and whose coverage grows with integration time (about
    12 % of the field in 0.1 s, 75 % in 1 s at 100k points/s). Deflections add as small-angle
    vectors (paraxial approximation), which keeps the pattern inside the nominal cone exactly.
    """

    model_config = _FROZEN

    kind: Literal["livox-mid70"] = "livox-mid70"
    fov_deg: float = Field(default=70.4, gt=0, lt=180, description="full cone angle")
    points_per_second: float = Field(default=100_000.0, gt=0)
    prism_rpm: tuple[float, float] = (7294.0, -4664.0)
    scan_period_s: float = Field(
        default=0.1, gt=0, description="one PointCloud2 message per period"
    )
    min_range_m: float = Field(default=0.05, ge=0)
    max_range_m: float = Field(default=40.0, gt=0)
    range_noise_m: float = Field(
        default=0.02, ge=0, description="sigma of the Gaussian range noise"
    )
    footprint_deg: float = Field(
        default=0.5,
        ge=0,
        description="half-angle of the beam footprint that mixes returns at edges",
    )

    @property
    def optical_axis(self) -> NDArray[np.float64]:
        """Centre of the scan pattern in the LiDAR frame."""
        return np.array([1.0, 0.0, 0.0])

    @property
    def scan_pattern(self) -> ScanPattern:
        return ScanPattern.NON_REPETITIVE

    def point_fields(self, points: NDArray[np.float64]) -> dict[str, NDArray[np.generic]]:
        """Fields the driver publishes beside x, y, z (the reader ignores intensity)."""
        return {}

    def rate(self, rate_scale: float = 1.0) -> float:
        return self.points_per_second * rate_scale

    def firing(self, t0: float, duration: float, rate_scale: float = 1.0) -> Firing:
        """Rays fired in `[t0, t0 + duration)`; `rate_scale` thins the firings, not the pattern."""
        t = _grid_times(t0, duration, self.rate(rate_scale))
        amplitude = math.radians(self.fov_deg) / 4.0  # two prisms, each a quarter of the full cone
        w1, w2 = (2.0 * math.pi * rpm / 60.0 for rpm in self.prism_rpm)
        deflection_y = amplitude * (np.cos(w1 * t) + np.cos(w2 * t))
        deflection_z = amplitude * (np.sin(w1 * t) + np.sin(w2 * t))
        off_axis = np.hypot(deflection_y, deflection_z)
        # sin(a) / a, safe at the pattern's centre, turns the deflection into the direction.
        scale = np.sinc(off_axis / math.pi)
        directions = np.column_stack([np.cos(off_axis), scale * deflection_y, scale * deflection_z])
        return Firing(times=t, directions=directions)


class Mid360(BaseModel):
    """Livox Mid-360-like head: 360 deg of azimuth x `elevation_deg`, non-repetitive.

    `lasers` beams fire in turn, each sweeping its own slice of the elevation band with a fast
    sinusoid while the head spins; the two rates are incommensurate with each other and with the
    scan period, so the traces shift from one revolution to the next and the band keeps filling
    in with integration time. With `line_field` the driver publishes each point's laser as
    `line` (uint8), as Livox's driver does.
    """

    model_config = _FROZEN

    kind: Literal["livox-mid360"] = "livox-mid360"
    elevation_deg: tuple[float, float] = (-7.0, 52.0)
    points_per_second: float = Field(default=200_000.0, gt=0)
    lasers: int = Field(default=4, ge=1)
    spin_hz: float = Field(default=77.3, gt=0, description="head revolutions per second")
    sweep_hz: float = Field(default=1237.1, gt=0, description="elevation sweeps per second")
    scan_period_s: float = Field(default=0.1, gt=0)
    min_range_m: float = Field(default=0.1, ge=0)
    max_range_m: float = Field(default=40.0, gt=0)
    range_noise_m: float = Field(default=0.02, ge=0)
    footprint_deg: float = Field(default=0.5, ge=0)
    line_field: bool = True

    @property
    def optical_axis(self) -> NDArray[np.float64]:
        """Azimuth 0 at the middle of the elevation band (the head has no single axis)."""
        elevation = math.radians(sum(self.elevation_deg) / 2.0)
        return np.array([math.cos(elevation), 0.0, math.sin(elevation)])

    @property
    def scan_pattern(self) -> ScanPattern:
        return ScanPattern.NON_REPETITIVE

    def point_fields(self, points: NDArray[np.float64]) -> dict[str, NDArray[np.generic]]:
        """`line`: the laser whose slice of the band the point's elevation lies in."""
        if not self.line_field:
            return {}
        low, high = self.elevation_deg
        elevation = np.degrees(np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1])))
        line = np.clip(np.floor((elevation - low) / (high - low) * self.lasers), 0, self.lasers - 1)
        return {"line": line.astype(np.uint8)}

    def rate(self, rate_scale: float = 1.0) -> float:
        return self.points_per_second * rate_scale

    def firing(self, t0: float, duration: float, rate_scale: float = 1.0) -> Firing:
        """Rays fired in `[t0, t0 + duration)`; `rate_scale` thins the firings, not the pattern."""
        t = _grid_times(t0, duration, self.rate(rate_scale))
        # The laser follows the firing's index on the global grid, not its index in this span.
        laser = np.rint(t * self.rate(rate_scale)).astype(np.int64) % self.lasers
        low, high = (math.radians(v) for v in self.elevation_deg)
        width = (high - low) / self.lasers
        sweep = 0.5 + 0.5 * np.sin(2.0 * math.pi * self.sweep_hz * t + laser)
        elevation = low + width * (laser + sweep)
        azimuth = 2.0 * math.pi * self.spin_hz * t
        directions = np.column_stack(
            [
                np.cos(elevation) * np.cos(azimuth),
                np.cos(elevation) * np.sin(azimuth),
                np.sin(elevation),
            ]
        )
        return Firing(times=t, directions=directions)


BeamField = Literal["ring", "channel", "laser_id"]
"""Names drivers give the per-point beam index: `ring` (Velodyne, Ouster, Hesai drivers),
`channel` (Autoware's nebula), `laser_id` (Luminar)."""


class SpinningLidar(BaseModel):
    """Spinning multi-beam LiDAR (Velodyne-like): `beams` fixed elevations swept in azimuth.

    Only azimuths inside `azimuth_mask_deg` are kept (sensor frame, 0 = +x, counter-clockwise),
    as drivers do to cut the robot's own body or a neighbour's field of view out.
    """

    model_config = _FROZEN

    kind: Literal["spinning"] = "spinning"
    beams: int = Field(default=16, ge=1)
    elevation_deg: tuple[float, float] = (-15.0, 15.0)
    rotation_hz: float = Field(default=10.0, gt=0)
    azimuth_resolution_deg: float = Field(default=0.2, gt=0)
    azimuth_mask_deg: tuple[float, float] = (-180.0, 180.0)
    min_range_m: float = Field(default=0.3, ge=0)
    max_range_m: float = Field(default=40.0, gt=0)
    range_noise_m: float = Field(default=0.03, ge=0)
    footprint_deg: float = Field(default=0.4, ge=0)
    beam_field: BeamField | None = Field(
        default="ring", description="name of the per-point beam index field; None: no field"
    )

    @model_validator(mode="after")
    def _check_mask(self) -> SpinningLidar:
        low, high = self.azimuth_mask_deg
        if not -180.0 <= low < high <= 180.0:
            raise ValueError(
                f"azimuth_mask_deg {self.azimuth_mask_deg} must be (low, high) with "
                "-180 <= low < high <= 180; yaw the mount to look elsewhere"
            )
        return self

    @property
    def scan_period_s(self) -> float:
        return 1.0 / self.rotation_hz

    @property
    def scan_pattern(self) -> ScanPattern:
        return ScanPattern.REPETITIVE

    def point_fields(self, points: NDArray[np.float64]) -> dict[str, NDArray[np.generic]]:
        """The beam index (uint16, 0 = lowest elevation) as `beam_field`, as spinning LiDARs'
        drivers publish it; recovered from the point's elevation (range noise keeps directions)."""
        if self.beam_field is None:
            return {}
        low, high = self.elevation_deg
        elevation = np.degrees(np.arctan2(points[:, 2], np.hypot(points[:, 0], points[:, 1])))
        step = (high - low) / max(self.beams - 1, 1)
        ring = np.clip(np.rint((elevation - low) / step), 0, self.beams - 1)
        return {self.beam_field: ring.astype(np.uint16)}

    @property
    def optical_axis(self) -> NDArray[np.float64]:
        """Middle of the kept azimuths at the middle elevation: where the scan is centred."""
        azimuth = math.radians(sum(self.azimuth_mask_deg) / 2.0)
        elevation = math.radians(sum(self.elevation_deg) / 2.0)
        return np.array(
            [
                math.cos(elevation) * math.cos(azimuth),
                math.cos(elevation) * math.sin(azimuth),
                math.sin(elevation),
            ]
        )

    def rate(self, rate_scale: float = 1.0) -> float:
        """Points per second after the azimuth mask."""
        kept = (self.azimuth_mask_deg[1] - self.azimuth_mask_deg[0]) / 360.0
        return self._column_rate(rate_scale) * self.beams * kept

    def _column_rate(self, rate_scale: float) -> float:
        return 360.0 / self.azimuth_resolution_deg * self.rotation_hz * rate_scale

    def firing(self, t0: float, duration: float, rate_scale: float = 1.0) -> Firing:
        """Rays fired in `[t0, t0 + duration)`; `rate_scale` coarsens the azimuth step."""
        column_times = _grid_times(t0, duration, self._column_rate(rate_scale))
        azimuth_deg = np.mod(360.0 * self.rotation_hz * column_times + 180.0, 360.0) - 180.0
        low, high = self.azimuth_mask_deg
        keep = (azimuth_deg >= low) & (azimuth_deg <= high)
        column_times, azimuth = column_times[keep], np.radians(azimuth_deg[keep])
        elevation = np.radians(np.linspace(*self.elevation_deg, self.beams))
        # Beams of one column fire together; order the points column by column, as drivers do.
        az = np.repeat(azimuth, self.beams)
        el = np.tile(elevation, len(azimuth))
        directions = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        return Firing(times=np.repeat(column_times, self.beams), directions=directions)


LidarModel = Annotated[Mid70 | Mid360 | SpinningLidar, Field(discriminator="kind")]
"""Any scan model; each has `optical_axis`, `scan_period_s`, range limits and noise, `firing()`."""
