"""Small stop-and-go recordings with known truth, written with `RecordingWriter` for reader tests.

The robot turns in place by `turn_deg` and creeps forward between stops; every LiDAR sees floor
points (z = 0 in `odom`) expressed in its own frame with the TRUE pose and extrinsic, plus NaN and
zero points, so a test can check that the reader keeps exactly the right scans and frames.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.io.writer import RecordingWriter, WriterFormat
from pipeline.transforms import Matrix4, apply, from_xyz_rpy, invert

NS = 1_000_000_000

# base_link -> lidar_front directly; base_link -> rear_mount -> lidar_rear (a chain).
T_BASE_FRONT = from_xyz_rpy([0.35, 0.0, 0.55], [0.0, np.radians(30.0), 0.0])
T_BASE_MOUNT = from_xyz_rpy([-0.30, 0.05, 0.40], [0.0, 0.0, np.pi])
T_MOUNT_REAR = from_xyz_rpy([0.02, 0.0, 0.10], [0.0, np.radians(25.0), 0.0])
TRUE_EXTRINSICS = {"lidar_front": T_BASE_FRONT, "lidar_rear": T_BASE_MOUNT @ T_MOUNT_REAR}
PERTURBATION = from_xyz_rpy([0.05, -0.03, 0.02], np.radians([1.0, -2.0, 3.0]))


@dataclass(frozen=True)
class Spec:
    """What to write. Times in seconds; the recording starts at `t0` (not zero, as real clocks)."""

    stops: int = 3
    dwell_s: float = 2.0
    move_s: float = 1.0
    turn_deg: float = 40.0
    step_m: float = 0.15
    t0: float = 100.0
    odom_hz: float = 50.0
    scan_hz: float = 10.0
    points: int = 300
    nan_fraction: float = 0.1
    zero_fraction: float = 0.05
    trajectory: Literal["odometry", "tf", "none"] = "odometry"
    odom_error_m: float = 0.0
    """Odometry offset added at stop k: k * odom_error_m along x (an initial S that is off)."""
    tf_static: bool = True
    lidars: Sequence[str] = ("lidar_front", "lidar_rear")
    float64_lidars: Sequence[str] = ("lidar_rear",)
    big_endian_lidars: Sequence[str] = ("lidar_rear",)
    ring_lidars: Sequence[str] = ("lidar_rear",)
    """Their scans carry a uint16 `ring` field, as spinning LiDARs' drivers publish."""
    nan_fraction_of: dict[str, float] = field(default_factory=dict)
    """Per-LiDAR override of `nan_fraction` (1.0: a dead LiDAR)."""
    footprint_height: float | None = None
    """If set, odometry moves `base_footprint`, this far below `base_link` (a tf_static edge)."""
    frame_prefix: str = ""
    """Written before every frame id (`/` as ROS 1 tf used to)."""
    header_clock_offset_ns: int | Mapping[str, int] = 0
    """Header stamps = log times + this, for every topic or by topic (see `RecordingWriter`)."""
    seed: int = 7


@dataclass(frozen=True)
class Truth:
    """Stop spans (s), true `T_odom_base` per stop, true and initial (tf_static) `T_base_lidar`."""

    stop_spans: list[tuple[float, float]]
    T_odom_base: list[Matrix4]
    T_odom_base_odometry: list[Matrix4]
    T_base_lidar: dict[str, Matrix4]
    T_base_lidar_initial: dict[str, Matrix4]
    valid_per_scan: dict[str, int]


def pose_at(spec: Spec, t: float, *, with_error: bool = False) -> Matrix4:
    """True (or odometry) `T_odom_base` at time `t`: stop k spans [k*(dwell+move), +dwell]."""
    return _pose_since_start(spec, t - spec.t0, with_error=with_error)


def _stamps_ns(spec: Spec, hz: float) -> NDArray[np.int64]:
    """Stamps every 1/hz from the first stop's start to the last one's end (both included), in
    integer nanoseconds: float seconds at a wall clock's epoch would round the last one away."""
    duration_ns = round(((spec.stops - 1) * (spec.dwell_s + spec.move_s) + spec.dwell_s) * NS)
    period_ns = round(NS / hz)
    return round(spec.t0 * NS) + np.arange(duration_ns // period_ns + 1) * period_ns


def _pose_since_start(spec: Spec, rel: float, *, with_error: bool = False) -> Matrix4:
    cycle = spec.dwell_s + spec.move_s
    rel = max(rel, 0.0)
    k = min(int(rel // cycle), spec.stops - 1)
    frac = (
        0.0 if rel - k * cycle <= spec.dwell_s else (rel - k * cycle - spec.dwell_s) / spec.move_s
    )
    progress = k + min(frac, 1.0) if k < spec.stops - 1 else float(k)
    T = from_xyz_rpy(
        [spec.step_m * progress, 0.0, 0.0], [0.0, 0.0, np.radians(spec.turn_deg * progress)]
    )
    if with_error:
        T[0, 3] += spec.odom_error_m * progress
    return T


def write_recording(path: Path, fmt: WriterFormat, spec: Spec = Spec()) -> Truth:
    """Write the recording of `spec` at `path` in `fmt`; return its truth."""
    rng = np.random.default_rng(spec.seed)
    cycle = spec.dwell_s + spec.move_s
    initial = {name: TRUE_EXTRINSICS[name] @ PERTURBATION for name in spec.lidars}
    n_zero = int(spec.points * spec.zero_fraction)
    n_nan = {
        name: int(spec.points * spec.nan_fraction_of.get(name, spec.nan_fraction))
        for name in spec.lidars
    }
    n_nan = {name: min(n, spec.points - n_zero) for name, n in n_nan.items()}
    n_valid = {name: spec.points - n_nan[name] - n_zero for name in spec.lidars}
    f = spec.frame_prefix
    T_footprint_base = from_xyz_rpy([0.0, 0.0, spec.footprint_height or 0.0], [0.0, 0.0, 0.0])
    with RecordingWriter(path, fmt, header_clock_offset_ns=spec.header_clock_offset_ns) as writer:
        if spec.tf_static:
            edges = (
                [(f + "base_link", f + "lidar_front", initial["lidar_front"])]
                if "lidar_front" in initial
                else []
            )
            if "lidar_rear" in initial:
                # Perturb the chain's last edge so that the composed chain equals `initial`.
                T_mount_rear = invert(T_BASE_MOUNT) @ initial["lidar_rear"]
                edges += [
                    (f + "base_link", f + "rear_mount", T_BASE_MOUNT),
                    (f + "rear_mount", f + "lidar_rear", T_mount_rear),
                ]
            if spec.footprint_height is not None:
                edges.append((f + "base_footprint", f + "base_link", T_footprint_base))
            writer.write_transforms(int(spec.t0 * NS), edges, static=True)
        for stamp in _stamps_ns(spec, spec.odom_hz).tolist():
            T = _pose_since_start(spec, (stamp - round(spec.t0 * NS)) / NS, with_error=True)
            child = "base_link"
            if spec.footprint_height is not None:
                T, child = T @ invert(T_footprint_base), "base_footprint"
            if spec.trajectory == "odometry":
                writer.write_odometry(
                    "/odom", stamp, T, odom_frame=f + "odom", base_frame=f + child
                )
            elif spec.trajectory == "tf":
                writer.write_transforms(stamp, [(f + "odom", f + child, T)])
        for stamp in _stamps_ns(spec, spec.scan_hz).tolist():
            T_odom_base = _pose_since_start(spec, (stamp - round(spec.t0 * NS)) / NS)
            for name in spec.lidars:
                radius = rng.uniform(1.0, 4.0, n_valid[name])
                angle = rng.uniform(0, 2 * np.pi, n_valid[name])
                floor = np.c_[
                    radius * np.cos(angle), radius * np.sin(angle), np.zeros(n_valid[name])
                ]
                floor[:, :2] += T_odom_base[:2, 3]
                in_lidar = apply(invert(T_odom_base @ TRUE_EXTRINSICS[name]), floor)
                junk = np.r_[np.full((n_nan[name], 3), np.nan), np.zeros((n_zero, 3))]
                stacked: NDArray[np.float64] = np.r_[in_lidar, junk]
                points = stacked[rng.permutation(len(stacked))]
                writer.write_pointcloud(
                    f"/{name}/points",
                    stamp,
                    f + name,
                    points,
                    extra_fields={
                        "intensity": rng.uniform(0, 100, len(points)),
                        **(
                            {"ring": np.arange(len(points), dtype=np.uint16) % 16}
                            if name in spec.ring_lidars
                            else {}
                        ),
                    },
                    dtype=np.float64 if name in spec.float64_lidars else np.float32,
                    big_endian=name in spec.big_endian_lidars,
                )
    spans = [(spec.t0 + k * cycle, spec.t0 + k * cycle + spec.dwell_s) for k in range(spec.stops)]
    return Truth(
        stop_spans=spans,
        T_odom_base=[pose_at(spec, a + 0.5) for a, _ in spans],
        T_odom_base_odometry=[pose_at(spec, a + 0.5, with_error=True) for a, _ in spans],
        T_base_lidar={name: TRUE_EXTRINSICS[name] for name in spec.lidars},
        T_base_lidar_initial=initial,
        valid_per_scan=n_valid,
    )
