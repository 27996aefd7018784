"""Small stop-and-go recordings with known truth, written with `RecordingWriter` for reader tests.

The robot turns in place by `turn_deg` and creeps forward between stops; every LiDAR sees floor
points (z = 0 in `odom`) expressed in its own frame with the TRUE pose and extrinsic, plus NaN and
zero points, so a test can check that the reader keeps exactly the right scans and frames.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.io.typestores import POINTCLOUD2
from pipeline.io.writer import RecordingWriter, WriterFormat
from pipeline.synth.lidar_models import LidarModel
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
    beam_field: str = "ring"
    """The name of that field (nebula drivers: `channel`, Luminar: `laser_id`)."""
    models: Mapping[str, LidarModel] = field(default_factory=dict)
    """LiDAR name -> synthesiser scan model: its scans fire the model's directions (at
    `model_rate_scale`, ranges 1-10 m) instead of floor points; `ring` from the model."""
    model_rate_scale: float = 0.1
    organised_lidars: Sequence[str] = ()
    """Their scans are organised clouds, `organised_rows` rows with padding at each row's end."""
    organised_rows: int = 4
    radar_topics: Sequence[str] = ()
    """Extra PointCloud2 topics with a radar's fields (`rcs`, `v_r`, `snr`), one frame each."""
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
    initial = {name: TRUE_EXTRINSICS[name] @ PERTURBATION for name in spec.lidars}
    counts = _point_counts(spec)
    with RecordingWriter(path, fmt, header_clock_offset_ns=spec.header_clock_offset_ns) as writer:
        if spec.tf_static:
            writer.write_transforms(int(spec.t0 * NS), _static_edges(spec, initial), static=True)
        _write_trajectory(writer, spec)
        for stamp in _stamps_ns(spec, spec.scan_hz).tolist():
            t = spec.t0 + (stamp - round(spec.t0 * NS)) / NS
            for name in spec.lidars:
                _write_lidar_scan(writer, spec, name, stamp, t, counts[name], rng)
            _write_radar_scans(writer, spec, stamp, rng)
    cycle = spec.dwell_s + spec.move_s
    spans = [(spec.t0 + k * cycle, spec.t0 + k * cycle + spec.dwell_s) for k in range(spec.stops)]
    return Truth(
        stop_spans=spans,
        T_odom_base=[pose_at(spec, a + 0.5) for a, _ in spans],
        T_odom_base_odometry=[pose_at(spec, a + 0.5, with_error=True) for a, _ in spans],
        T_base_lidar={name: TRUE_EXTRINSICS[name] for name in spec.lidars},
        T_base_lidar_initial=initial,
        valid_per_scan={name: valid for name, (valid, _nan, _zero) in counts.items()},
    )


def _point_counts(spec: Spec) -> dict[str, tuple[int, int, int]]:
    """Per LiDAR: valid, NaN and zero points of each floor scan (NaN ones capped so that the
    zero ones always fit)."""
    n_zero = int(spec.points * spec.zero_fraction)
    counts = {}
    for name in spec.lidars:
        n_nan = int(spec.points * spec.nan_fraction_of.get(name, spec.nan_fraction))
        n_nan = min(n_nan, spec.points - n_zero)
        counts[name] = (spec.points - n_nan - n_zero, n_nan, n_zero)
    return counts


def _footprint(spec: Spec) -> Matrix4:
    """`T_footprint_base`: `base_link` `footprint_height` above `base_footprint` (or on it)."""
    return from_xyz_rpy([0.0, 0.0, spec.footprint_height or 0.0], [0.0, 0.0, 0.0])


def _static_edges(spec: Spec, initial: Mapping[str, Matrix4]) -> list[tuple[str, str, Matrix4]]:
    """The tf_static edges (parent, child, `T_parent_child`) whose chains give `initial`."""
    f = spec.frame_prefix
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
        edges.append((f + "base_footprint", f + "base_link", _footprint(spec)))
    return edges


def _write_trajectory(writer: RecordingWriter, spec: Spec) -> None:
    """The odometry (with its error) as `spec.trajectory` says: Odometry messages on `/odom`,
    dynamic tf, or nothing."""
    f = spec.frame_prefix
    T_footprint_base = _footprint(spec)
    for stamp in _stamps_ns(spec, spec.odom_hz).tolist():
        T = _pose_since_start(spec, (stamp - round(spec.t0 * NS)) / NS, with_error=True)
        child = "base_link"
        if spec.footprint_height is not None:
            T, child = T @ invert(T_footprint_base), "base_footprint"
        if spec.trajectory == "odometry":
            writer.write_odometry("/odom", stamp, T, odom_frame=f + "odom", base_frame=f + child)
        elif spec.trajectory == "tf":
            writer.write_transforms(stamp, [(f + "odom", f + child, T)])


def _write_lidar_scan(
    writer: RecordingWriter,
    spec: Spec,
    name: str,
    stamp: int,
    t: float,
    counts: tuple[int, int, int],
    rng: np.random.Generator,
) -> None:
    """LiDAR `name`'s scan at `t` (its model's firing, or floor points with `counts` of valid,
    NaN and zero ones), in the field layout, type, byte order and organisation `spec` gives it."""
    if name in spec.models:
        points, beams = _model_scan(spec, spec.models[name], t, rng)
    else:
        points, beams = _floor_scan(spec, name, t, counts, rng)
    fields: dict[str, NDArray[Any]] = {"intensity": rng.uniform(0, 100, len(points))}
    if name in spec.ring_lidars:
        fields[spec.beam_field] = beams
    dtype = np.float64 if name in spec.float64_lidars else np.float32
    frame_id = spec.frame_prefix + name
    if name in spec.organised_lidars:
        write_organised_cloud(
            writer,
            f"/{name}/points",
            stamp,
            frame_id,
            points,
            fields,
            spec.organised_rows,
            dtype=dtype,
        )
    else:
        writer.write_pointcloud(
            f"/{name}/points",
            stamp,
            frame_id,
            points,
            extra_fields=fields,
            dtype=dtype,
            big_endian=name in spec.big_endian_lidars,
        )


def _write_radar_scans(
    writer: RecordingWriter, spec: Spec, stamp: int, rng: np.random.Generator
) -> None:
    """30 random detections with a radar's fields on each of `spec.radar_topics`."""
    for k, topic in enumerate(spec.radar_topics):
        detections = rng.uniform(-20, 20, (30, 3))
        writer.write_pointcloud(
            topic,
            stamp,
            f"{spec.frame_prefix}radar_{k}",
            detections,
            extra_fields={
                "rcs": rng.uniform(-10, 30, 30).astype(np.float32),
                "v_r": rng.uniform(-5, 5, 30).astype(np.float32),
                "snr": rng.uniform(0, 40, 30).astype(np.float32),
            },
        )


def _floor_scan(
    spec: Spec, name: str, t: float, counts: tuple[int, int, int], rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.uint16]]:
    """Floor points seen with the TRUE pose and extrinsic at `t`, mixed with NaN and zero
    points (`counts`: valid, NaN, zero), and a made-up beam index."""
    valid, nan, zero = counts
    T_odom_base = pose_at(spec, t)
    radius = rng.uniform(1.0, 4.0, valid)
    angle = rng.uniform(0, 2 * np.pi, valid)
    floor = np.c_[radius * np.cos(angle), radius * np.sin(angle), np.zeros(valid)]
    floor[:, :2] += T_odom_base[:2, 3]
    in_lidar = apply(invert(T_odom_base @ TRUE_EXTRINSICS[name]), floor)
    junk = np.r_[np.full((nan, 3), np.nan), np.zeros((zero, 3))]
    stacked: NDArray[np.float64] = np.r_[in_lidar, junk]
    points = stacked[rng.permutation(len(stacked))]
    return points, (np.arange(len(points)) % 16).astype(np.uint16)


def _model_scan(
    spec: Spec, model: LidarModel, t: float, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.uint16]]:
    """The directions `model` fires in the scan starting at `t`, at random ranges (1-10 m)."""
    firing = model.firing(t - spec.t0, model.scan_period_s, spec.model_rate_scale)
    points = firing.directions * rng.uniform(1.0, 10.0, (len(firing), 1))
    beams = model.point_fields(points).get("ring")
    if beams is None:
        beams = np.zeros(len(points))
    return points, np.asarray(beams, dtype=np.uint16)


def write_organised_cloud(
    writer: RecordingWriter,
    topic: str,
    stamp_ns: int,
    frame_id: str,
    points: NDArray[np.float64],
    fields: Mapping[str, NDArray[Any]],
    rows: int,
    *,
    dtype: type[np.floating[Any]] = np.float32,
    row_padding: int = 8,
) -> None:
    """One organised PointCloud2 (`height = rows`, as Ouster drivers publish), each row padded
    with `row_padding` bytes; `len(points)` must be a multiple of `rows`."""
    columns = len(points) // rows
    assert columns * rows == len(points), f"{len(points)} points do not fill {rows} rows"
    names = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    record = np.zeros(
        len(points),
        dtype=[(n, dtype) for n in names] + [(n, v.dtype) for n, v in fields.items()],
    )
    for name, values in {**names, **fields}.items():
        record[name] = values
    codes = {"u1": 2, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}
    point_field = writer.types["sensor_msgs/msg/PointField"]
    offsets: dict[str, tuple[Any, ...]] = dict(record.dtype.fields or {})
    rows_bytes = record.view(np.uint8).reshape(rows, columns * record.dtype.itemsize)
    padded = np.concatenate([rows_bytes, np.zeros((rows, row_padding), np.uint8)], axis=1)
    types = writer.types
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_ns // NS, nanosec=stamp_ns % NS)
    ros1 = {"seq": 0} if writer.format is WriterFormat.ROS1 else {}
    msg = types[POINTCLOUD2](
        header=types["std_msgs/msg/Header"](**ros1, stamp=stamp, frame_id=frame_id),
        height=rows,
        width=columns,
        fields=[
            point_field(name=name, offset=int(offset), datatype=codes[sub.str[1:]], count=1)
            for name, (sub, offset, *_) in offsets.items()
        ],
        is_bigendian=False,
        point_step=record.dtype.itemsize,
        row_step=columns * record.dtype.itemsize + row_padding,
        data=padded.reshape(-1),
        is_dense=False,
    )
    writer.write_raw(topic, POINTCLOUD2, stamp_ns, msg)
