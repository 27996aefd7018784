"""Write a synthetic scenario as a recording that follows the input contract, with its truth.

`out_dir/recording/` is a ROS 2 bag (MCAP): one PointCloud2 topic per LiDAR (`/<frame>/points`,
fields x, y, z, intensity as float32, in the LiDAR frame), `nav_msgs/Odometry` on `/odom`
(`odom -> base_link`, continuous, with the twist) and `/tf_static` holding the *perturbed*
extrinsics (through a mount frame where the scenario has one). With `ros1`, `recording.bag`
holds the same messages. `truth.json` and `labels.npz` hold what the recording hides.
"""

from __future__ import annotations

import contextlib
import dataclasses
import heapq
import tarfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import BadInputError
from pipeline.io.writer import RecordingWriter, WriterFormat
from pipeline.synth.scenarios import ScenarioSpec
from pipeline.synth.simulate import LabelledScan, World, labels_of, make_world
from pipeline.synth.truth import Truth, write_truth
from pipeline.transforms import Matrix4, invert

RECORDING_DIR = "recording"
ROS1_FILE = "recording.bag"
ODOMETRY_TOPIC = "/odom"
_NS = 1_000_000_000
_EMPTY_POINTS = np.zeros((0, 3))
_EMPTY = np.zeros(0)
_EMPTY32 = np.zeros(0, dtype=np.float32)


def write_recording(
    scenario: str | ScenarioSpec,
    out_dir: Path | str,
    seed: int = 0,
    rate_scale: float = 1.0,
    ros1: bool = False,
    progress: Callable[[str], None] | None = None,
) -> Truth:
    """Synthesise `scenario` into `out_dir` (created; it must not exist or be empty).

    The same scenario, seed and rate give the same point data and truth, byte for byte.
    `progress` receives a line per stop reached.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise BadInputError(
            f"output directory {out_dir} already exists and is not empty; choose a new --out "
            "directory or delete this one"
        )
    world = make_world(scenario, seed, rate_scale)
    out_dir.mkdir(parents=True, exist_ok=True)
    offsets = world.spec.header_clock_offset_ns
    writers = [_writer(out_dir / RECORDING_DIR, WriterFormat.ROS2_MCAP, offsets)]
    if ros1:
        writers.append(_writer(out_dir / ROS1_FILE, WriterFormat.ROS1, offsets))
    labels: dict[str, list[LabelledScan]] = {mount.frame: [] for mount in world.spec.lidars}
    odometry = _odometry(world)
    with contextlib.ExitStack() as stack:
        for writer in writers:
            stack.enter_context(writer)
            writer.write_transforms(world.spec.start_time_ns, _static_edges(world), static=True)
        for lidar_index, index in _message_order(world, odometry, progress):
            if lidar_index < 0:
                for writer in writers:
                    odometry.write(writer, index)
                continue
            scan = world.simulate_scan(lidar_index, index)
            mount = world.spec.lidars[lidar_index]
            for writer in writers:
                writer.write_pointcloud(
                    mount.topic,
                    scan.stamp_ns,
                    mount.frame,
                    scan.points,
                    extra_fields={
                        "intensity": scan.intensity,
                        **mount.model.point_fields(scan.points),
                    },
                )
            # Only the labels are kept (the points went to the bag): memory stays small.
            labels[mount.frame].append(
                dataclasses.replace(scan, points=_EMPTY_POINTS, times=_EMPTY, intensity=_EMPTY32)
            )
    truth = world.truth({frame: labels_of(items) for frame, items in labels.items()})
    write_truth(truth, out_dir)
    return truth


def archive_recording(out: Path, archive: Path) -> Path:
    """The ROS 2 bag directory `write_recording` wrote under `out`, as one tar file `archive`:
    what a robot uploads (a bag directory travels as one archive)."""
    with tarfile.open(archive, "w") as tar:
        tar.add(out / RECORDING_DIR, arcname=RECORDING_DIR)
    return archive


def _writer(path: Path, fmt: WriterFormat, offsets: Mapping[str, int]) -> RecordingWriter:
    """A writer whose header stamps are the log time plus the topic's offset in `offsets`."""
    return RecordingWriter(path, fmt, header_clock_offset_ns=offsets)


def _static_edges(world: World) -> list[tuple[str, str, Matrix4]]:
    """`/tf_static` edges with the initial extrinsics; mount frames published once each."""
    base = world.spec.base_frame
    edges: list[tuple[str, str, Matrix4]] = []
    mounts: set[str] = set()
    for mount, T_base_lidar in zip(world.spec.lidars, world.T_base_lidar_initial, strict=True):
        if mount.via is None:
            edges.append((base, mount.frame, T_base_lidar))
            continue
        T_base_mount = mount.via.T_base_mount()
        if mount.via.frame not in mounts:
            mounts.add(mount.via.frame)
            edges.append((base, mount.via.frame, T_base_mount))
        edges.append((mount.via.frame, mount.frame, invert(T_base_mount) @ T_base_lidar))
    return edges


@dataclass(frozen=True)
class _Odometry:
    """The odometry messages: stamps (K,) ns, `T_odom_base` (K, 4, 4), twist (K, 3) twice."""

    world: World
    stamps_ns: NDArray[np.int64]
    T_odom_base: NDArray[np.float64]
    linear: NDArray[np.float64]
    angular: NDArray[np.float64]

    def write(self, writer: RecordingWriter, index: int) -> None:
        writer.write_odometry(
            ODOMETRY_TOPIC,
            int(self.stamps_ns[index]),
            self.T_odom_base[index],
            odom_frame=self.world.spec.odom_frame,
            base_frame=self.world.spec.base_frame,
            linear_velocity=self.linear[index].tolist(),
            angular_velocity=self.angular[index].tolist(),
        )


def _odometry(world: World) -> _Odometry:
    """Odometry at `odometry_hz` from the first stop's start to the last stop's end."""
    hz = world.spec.odometry_hz
    count = int(world.duration_s * hz + 1e-9) + 1
    offsets_ns = np.round(np.arange(count) * (_NS / hz)).astype(np.int64)
    t = offsets_ns / _NS
    linear, angular = world.spec.motion.twist(t)
    return _Odometry(
        world, world.spec.start_time_ns + offsets_ns, world.odometry(t), linear, angular
    )


def _message_order(
    world: World, odometry: _Odometry, progress: Callable[[str], None] | None
) -> Iterator[tuple[int, int]]:
    """`(lidar_index, scan_index)` of every message in time order; `lidar_index` -1 is the
    odometry message `scan_index`. At equal stamps odometry comes first."""
    queues = [_queue(-1, odometry.stamps_ns - world.spec.start_time_ns)]
    for i in range(len(world.spec.lidars)):
        period = world.scan_period_ns(i)
        queues.append(_queue(i, np.arange(world.scan_count(i), dtype=np.int64) * period))
    stop_starts = [round(a * _NS) for a, _ in world.stop_times]
    reported = 0
    for offset, lidar_index, index in heapq.merge(*queues):
        while progress and reported < len(stop_starts) and offset >= stop_starts[reported]:
            reported += 1
            progress(f"{world.spec.name}: stop {reported}/{len(stop_starts)}")
        yield lidar_index, index


def _queue(lidar_index: int, offsets_ns: NDArray[np.int64]) -> Iterator[tuple[int, int, int]]:
    """Sort keys `(offset_ns, lidar_index, message_index)` of one topic's messages."""
    for index, offset in enumerate(offsets_ns.tolist()):
        yield offset, lidar_index, index
