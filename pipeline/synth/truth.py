"""Ground truth of a synthetic recording: true and initial poses, objects, per-point noise labels.

On disk (`write_recording`): `truth.json` beside a compressed `labels.npz`; `load_truth` reads
both back. Layout of `labels.npz`, per LiDAR frame `F` (key names are `F/<name>`):
  - `F/stamps_ns` (S,) int64: bag log time of each PointCloud2 message, in publication order
    (the time of the scan's first firing; the scan lasts `scan_period_s`); its header stamp is
    the same plus the topic's `spec.header_clock_offset_ns`, where the scenario offsets it;
  - `F/offsets` (S + 1,) int64: message `s` holds points `offsets[s]:offsets[s + 1]` below;
  - `F/is_bleeding` (N,) bool: the point is a mixed return floating between two surfaces;
  - `F/object_index` (N,) int16: the object the point lies on (index into `objects`), -1 the floor,
    -2 none of them (a walker or dust);
  - `F/is_moving` (N,) bool: the point lies on a walker (a person or cart walking by);
  - `F/is_spurious` (N,) bool: a return from dust near the sensor, on no surface.
`truth.json` also holds the analytic floor (`floor`, null for the plane z = 0), the walkers' ways
(`walkers`) and, per stop, the base's true height, roll and pitch on that floor (`base_on_floor`).
Points keep the order of the message's data, so labels line up with a decoded cloud point by point.
Stop times are on the bag's log clock too. `spec` holds the whole scenario (every drawn factor of
a randomised one) and `scenario_class` its benchmark class.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pipeline.errors import BadInputError
from pipeline.synth.floor import FloorSurface
from pipeline.synth.objects import ObjectKind, ObjectRole, SceneObject
from pipeline.synth.walkers import Walker
from pipeline.transforms import (
    Matrix4,
    from_translation_xyzw,
    invert,
    pose_difference,
    to_translation_xyzw,
)

SCHEMA_VERSION = 1
TRUTH_FILE = "truth.json"
LABELS_FILE = "labels.npz"
_NS = 1_000_000_000


@dataclass(frozen=True)
class PointLabels:
    """Labels of a cloud, point by point: `is_bleeding` (N,) bool, `object_index` (N,) int16,
    `is_moving` (N,) bool, `is_spurious` (N,) bool (the module docstring says what each means)."""

    is_bleeding: NDArray[np.bool_]
    object_index: NDArray[np.int16]
    is_moving: NDArray[np.bool_]
    is_spurious: NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.is_bleeding)


@dataclass(frozen=True)
class ScanLabels:
    """The labels of every message of one LiDAR (see the module docstring for the layout)."""

    stamps_ns: NDArray[np.int64]
    offsets: NDArray[np.int64]
    is_bleeding: NDArray[np.bool_]
    object_index: NDArray[np.int16]
    is_moving: NDArray[np.bool_]
    is_spurious: NDArray[np.bool_]

    def between(
        self, t_start_ns: int, t_end_ns: int, after_ns: int, before_ns: int = 0
    ) -> PointLabels:
        """Labels of the scans with `stamp - before_ns >= t_start_ns` and
        `stamp + after_ns <= t_end_ns`, in message order.

        `after_ns = period, before_ns = 0` is "wholly inside" for stamps at the scan's start (how
        this synthesiser stamps); `before_ns = after_ns = period` is the reader's rule, which
        does not know which end of the scan a driver stamps.
        """
        inside = (self.stamps_ns - before_ns >= t_start_ns) & (
            self.stamps_ns + after_ns <= t_end_ns
        )
        chosen = np.flatnonzero(inside)
        index = (
            np.concatenate([np.arange(self.offsets[s], self.offsets[s + 1]) for s in chosen])
            if len(chosen)
            else np.zeros(0, dtype=np.int64)
        )
        return PointLabels(
            self.is_bleeding[index],
            self.object_index[index],
            self.is_moving[index],
            self.is_spurious[index],
        )


@dataclass(frozen=True)
class LidarTruth:
    """One LiDAR: its true and initial (`/tf_static`) extrinsic, both `T_base_lidar` (4, 4)."""

    frame: str
    topic: str
    model: str
    optical_axis: NDArray[np.float64]
    scan_period_s: float
    T_base_lidar_true: Matrix4
    T_base_lidar_initial: Matrix4

    @property
    def perturbation(self) -> Matrix4:
        """`delta` with `T_base_lidar_initial = T_base_lidar_true @ delta`."""
        return invert(self.T_base_lidar_true) @ self.T_base_lidar_initial


@dataclass(frozen=True)
class StopTruth:
    """One stop: true still interval (ROS seconds) and true / odometry pose of the base."""

    index: int
    t_start: float
    t_end: float
    T_odom_base_true: Matrix4
    T_odom_base_initial: Matrix4


@dataclass(frozen=True)
class Truth:
    """Everything the synthesiser knows and the recording hides."""

    scenario: str
    seed: int
    rate_scale: float
    base_frame: str
    odom_frame: str
    reference_frame: str
    lidars: tuple[LidarTruth, ...]
    stops: tuple[StopTruth, ...]
    objects: tuple[SceneObject, ...]
    labels: Mapping[str, ScanLabels] = field(default_factory=dict)
    scenario_class: str = ""
    spec: Mapping[str, Any] = field(default_factory=dict)
    """The whole `ScenarioSpec` as JSON: every factor the recording was drawn with."""
    floor: FloorSurface | None = None
    walkers: tuple[Walker, ...] = ()

    def lidar(self, frame: str) -> LidarTruth:
        for lidar in self.lidars:
            if lidar.frame == frame:
                return lidar
        raise KeyError(f"no LiDAR {frame!r} in the truth; it has {[x.frame for x in self.lidars]}")

    def T_ref_lidar_true(self, frame: str) -> Matrix4:
        """True `T_ref_lidar`: maps `frame`'s points into the reference LiDAR's frame."""
        return (
            invert(self.lidar(self.reference_frame).T_base_lidar_true)
            @ self.lidar(frame).T_base_lidar_true
        )

    def stop_labels(self, stop_index: int, frame: str) -> PointLabels:
        """Labels lined up with `simulate_problem`'s cloud of this stop (the scans wholly inside
        the true stop interval)."""
        stop = self.stops[stop_index]
        return self.labels[frame].between(
            _to_ns(stop.t_start), _to_ns(stop.t_end), self._period_ns(frame)
        )

    def labels_between(self, t_start: float, t_end: float, frame: str) -> PointLabels:
        """Labels lined up with the cloud `pipeline.io.read_recording` accumulates for a stop it
        found from `t_start` to `t_end` (ROS seconds): its rule keeps a scan when both
        `stamp - period` and `stamp + period` lie inside the stop."""
        period = self._period_ns(frame)
        return self.labels[frame].between(_to_ns(t_start), _to_ns(t_end), period, period)

    def _period_ns(self, frame: str) -> int:
        return round(self.lidar(frame).scan_period_s * _NS)

    def to_json(self) -> dict[str, Any]:
        return {
            "schema_version": SCHEMA_VERSION,
            "scenario": self.scenario,
            "seed": self.seed,
            "rate_scale": self.rate_scale,
            "base_frame": self.base_frame,
            "odom_frame": self.odom_frame,
            "reference_frame": self.reference_frame,
            "lidars": {
                lidar.frame: {
                    "topic": lidar.topic,
                    "model": lidar.model,
                    "optical_axis": lidar.optical_axis.tolist(),
                    "scan_period_s": lidar.scan_period_s,
                    "T_base_lidar_true": _pose_json(lidar.T_base_lidar_true),
                    "T_base_lidar_initial": _pose_json(lidar.T_base_lidar_initial),
                    "perturbation": _difference_json(
                        lidar.T_base_lidar_true, lidar.T_base_lidar_initial
                    ),
                }
                for lidar in self.lidars
            },
            "stops": [
                {
                    "index": stop.index,
                    "start": stop.t_start,
                    "end": stop.t_end,
                    "T_odom_base_true": _pose_json(stop.T_odom_base_true),
                    "T_odom_base_initial": _pose_json(stop.T_odom_base_initial),
                    "perturbation": _difference_json(
                        stop.T_odom_base_true, stop.T_odom_base_initial
                    ),
                    "base_on_floor": _tilt_json(stop.T_odom_base_true),
                }
                for stop in self.stops
            ],
            "objects": [obj.to_json() for obj in self.objects],
            "scenario_class": self.scenario_class,
            "spec": dict(self.spec),
            "floor": None if self.floor is None else self.floor.to_json(),
            "walkers": [walker.to_json() for walker in self.walkers],
            "labels": {
                "file": LABELS_FILE,
                "keys": {
                    frame: {name: f"{frame}/{name}" for name in _LABEL_ARRAYS}
                    for frame in self.labels
                },
                "layout": "per LiDAR frame F: F/stamps_ns (S,) int64 log times in message "
                "order (header stamp = log time + spec.header_clock_offset_ns[topic]); "
                "F/offsets (S+1,) int64, message s holds points offsets[s]:offsets[s+1]; "
                "F/is_bleeding (N,) bool; F/object_index (N,) int16, -1 = floor, -2 = a walker "
                "or dust; F/is_moving (N,) bool, on a walker; F/is_spurious (N,) bool, dust",
            },
        }


_LABEL_ARRAYS = (
    "stamps_ns",
    "offsets",
    "is_bleeding",
    "object_index",
    "is_moving",
    "is_spurious",
)


def write_truth(truth: Truth, out_dir: Path) -> None:
    """`truth.json` and `labels.npz` in `out_dir`, byte for byte the same for the same truth."""
    text = json.dumps(truth.to_json(), indent=2)
    (out_dir / TRUTH_FILE).write_text(text + "\n", encoding="utf-8")
    # np.savez stamps each member with the current time; a fixed date keeps the bytes reproducible.
    with zipfile.ZipFile(out_dir / LABELS_FILE, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for frame, labels in truth.labels.items():
            for name in _LABEL_ARRAYS:
                buffer = io.BytesIO()
                np.lib.format.write_array(buffer, np.ascontiguousarray(getattr(labels, name)))
                info = zipfile.ZipInfo(f"{frame}/{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                archive.writestr(info, buffer.getvalue())


def load_truth(out_dir: Path | str) -> Truth:
    """Read the truth `write_recording` left in `out_dir` (labels included)."""
    out_dir = Path(out_dir)
    doc = _read_truth_json(out_dir / TRUTH_FILE)
    labels = _read_labels(out_dir / doc["labels"]["file"], doc["labels"]["keys"])
    return Truth(
        scenario=doc["scenario"],
        seed=doc["seed"],
        rate_scale=doc["rate_scale"],
        base_frame=doc["base_frame"],
        odom_frame=doc["odom_frame"],
        reference_frame=doc["reference_frame"],
        lidars=tuple(_lidar_from_json(frame, entry) for frame, entry in doc["lidars"].items()),
        stops=tuple(_stop_from_json(entry) for entry in doc["stops"]),
        objects=tuple(_object_from_json(entry) for entry in doc["objects"]),
        labels=labels,
        scenario_class=doc.get("scenario_class", ""),
        spec=doc.get("spec", {}),
        floor=None if doc.get("floor") is None else FloorSurface.from_json(doc["floor"]),
        walkers=tuple(Walker.from_json(entry) for entry in doc.get("walkers", [])),
    )


def _read_truth_json(path: Path) -> dict[str, Any]:
    """`truth.json`, refused with what to do when it is missing, broken or of another schema."""
    try:
        doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise BadInputError(
            f"cannot read {path}: {err}; point at a directory written by `fleetcal synth`"
        ) from err
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise BadInputError(
            f"{path} has schema_version {doc.get('schema_version')!r}, this code reads "
            f"{SCHEMA_VERSION}; synthesise the recording again"
        )
    return doc


def _read_labels(path: Path, keys: Mapping[str, Mapping[str, str]]) -> dict[str, ScanLabels]:
    """Each frame's labels from `labels.npz`; `keys`: frame -> label name -> archive key."""
    labels: dict[str, ScanLabels] = {}
    with np.load(path) as archive:
        for frame, frame_keys in keys.items():
            arrays = {name: archive[key] for name, key in frame_keys.items()}
            # Recordings written before walkers and dust existed have neither label.
            for name in ("is_moving", "is_spurious"):
                arrays.setdefault(name, np.zeros(len(arrays["is_bleeding"]), dtype=bool))
            labels[frame] = ScanLabels(**arrays)
    return labels


def _lidar_from_json(frame: str, entry: Mapping[str, Any]) -> LidarTruth:
    return LidarTruth(
        frame=frame,
        topic=entry["topic"],
        model=entry["model"],
        optical_axis=np.asarray(entry["optical_axis"], dtype=np.float64),
        scan_period_s=entry["scan_period_s"],
        T_base_lidar_true=_pose_from_json(entry["T_base_lidar_true"]),
        T_base_lidar_initial=_pose_from_json(entry["T_base_lidar_initial"]),
    )


def _stop_from_json(entry: Mapping[str, Any]) -> StopTruth:
    return StopTruth(
        index=entry["index"],
        t_start=entry["start"],
        t_end=entry["end"],
        T_odom_base_true=_pose_from_json(entry["T_odom_base_true"]),
        T_odom_base_initial=_pose_from_json(entry["T_odom_base_initial"]),
    )


def _object_from_json(entry: Mapping[str, Any]) -> SceneObject:
    """An object of `truth.json`; recordings written before roles existed hold only objects."""
    return SceneObject(
        kind=ObjectKind(entry["kind"]),
        dimensions=entry["dimensions"],
        T_world_object=_pose_from_json(entry["pose"]),
        reflectivity=entry["reflectivity"],
        role=ObjectRole(entry.get("role", ObjectRole.OBJECT.value)),
    )


def _to_ns(t: float) -> int:
    """ROS seconds to nanoseconds. A float near 1.7e9 s resolves 0.2 us; stamps are whole us."""
    return round(t * 1e6) * 1000


def _pose_json(T: Matrix4) -> dict[str, list[float]]:
    translation, quat = to_translation_xyzw(T)
    return {"translation": translation.tolist(), "rotation_xyzw": quat.tolist()}


def _pose_from_json(entry: Mapping[str, Any]) -> Matrix4:
    return from_translation_xyzw(entry["translation"], entry["rotation_xyzw"])


def _tilt_json(T_world_base: Matrix4) -> dict[str, float]:
    """Height, roll and pitch of the base (fixed-axis roll, pitch, yaw): zero on a flat floor."""
    _yaw, pitch, roll = Rotation.from_matrix(T_world_base[:3, :3]).as_euler("ZYX", degrees=True)
    return {
        "height_m": float(T_world_base[2, 3]),
        "roll_deg": float(roll),
        "pitch_deg": float(pitch),
    }


def _difference_json(T_true: Matrix4, T_initial: Matrix4) -> dict[str, float]:
    translation, rotation = pose_difference(T_true, T_initial)
    return {"translation_m": translation, "rotation_deg": rotation}
