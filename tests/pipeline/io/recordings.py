"""Small stop-and-go recordings with known truth, written with `RecordingWriter` for reader tests.

The robot turns in place by `turn_deg` and creeps forward between stops; every LiDAR sees floor
points (z = 0 in `odom`) expressed in its own frame with the TRUE pose and extrinsic, plus NaN and
zero points, so a test can check that the reader keeps exactly the right scans and frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

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
    seed: int = 7


@dataclass(frozen=True)
class Truth:
    """Stop spans (s), true `T_odom_base` per stop, true and initial (tf_static) `T_base_lidar`."""

    stop_spans: list[tuple[float, float]]
    T_odom_base: list[Matrix4]
    T_odom_base_odometry: list[Matrix4]
    T_base_lidar: dict[str, Matrix4]
    T_base_lidar_initial: dict[str, Matrix4]
    valid_per_scan: int
    extra: dict[str, object] = field(default_factory=dict)


def pose_at(spec: Spec, t: float, *, with_error: bool = False) -> Matrix4:
    """True (or odometry) `T_odom_base` at time `t`: stop k spans [k*(dwell+move), +dwell]."""
    cycle = spec.dwell_s + spec.move_s
    rel = max(t - spec.t0, 0.0)
    k = min(int(rel // cycle), spec.stops - 1)
    frac = 0.0 if rel - k * cycle <= spec.dwell_s else (rel - k * cycle - spec.dwell_s) / spec.move_s
    progress = k + min(frac, 1.0) if k < spec.stops - 1 else float(k)
    T = from_xyz_rpy([spec.step_m * progress, 0.0, 0.0], [0.0, 0.0, np.radians(spec.turn_deg * progress)])
    if with_error:
        T[0, 3] += spec.odom_error_m * progress
    return T


def write_recording(path: Path, fmt: WriterFormat, spec: Spec = Spec()) -> Truth:
    """Write the recording of `spec` at `path` in `fmt`; return its truth."""
    rng = np.random.default_rng(spec.seed)
    cycle = spec.dwell_s + spec.move_s
    t_end = spec.t0 + (spec.stops - 1) * cycle + spec.dwell_s
    initial = {name: TRUE_EXTRINSICS[name] @ PERTURBATION for name in spec.lidars}
    n_nan = int(spec.points * spec.nan_fraction)
    n_zero = int(spec.points * spec.zero_fraction)
    n_valid = spec.points - n_nan - n_zero
    with RecordingWriter(path, fmt) as writer:
        if spec.tf_static:
            edges = [("base_link", "lidar_front", initial["lidar_front"])] if "lidar_front" in initial else []
            if "lidar_rear" in initial:
                # Perturb the chain's last edge so that the composed chain equals `initial`.
                T_mount_rear = invert(T_BASE_MOUNT) @ initial["lidar_rear"]
                edges += [("base_link", "rear_mount", T_BASE_MOUNT), ("rear_mount", "lidar_rear", T_mount_rear)]
            writer.write_transforms(int(spec.t0 * NS), edges, static=True)
        for t in np.arange(spec.t0, t_end + 1e-9, 1.0 / spec.odom_hz):
            stamp = int(round(t * NS))
            T = pose_at(spec, t, with_error=True)
            if spec.trajectory == "odometry":
                writer.write_odometry("/odom", stamp, T)
            elif spec.trajectory == "tf":
                writer.write_transforms(stamp, [("odom", "base_link", T)])
        for t in np.arange(spec.t0, t_end + 1e-9, 1.0 / spec.scan_hz):
            stamp = int(round(t * NS))
            T_odom_base = pose_at(spec, t)
            for name in spec.lidars:
                radius = rng.uniform(1.0, 4.0, n_valid)
                angle = rng.uniform(0, 2 * np.pi, n_valid)
                floor = np.c_[radius * np.cos(angle), radius * np.sin(angle), np.zeros(n_valid)]
                floor[:, :2] += T_odom_base[:2, 3]
                points = apply(invert(T_odom_base @ TRUE_EXTRINSICS[name]), floor)
                junk = np.r_[np.full((n_nan, 3), np.nan), np.zeros((n_zero, 3))]
                points = rng.permutation(np.r_[points, junk])
                writer.write_pointcloud(
                    f"/{name}/points", stamp, name, points,
                    extra_fields={"intensity": rng.uniform(0, 100, len(points))},
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
