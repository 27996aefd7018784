"""`CalibrationProblem`: what a recording gives the pipeline, free of the file it came from.

Frames: `odom` is the odometry's fixed frame, `base` the robot body (`base_link`), each LiDAR
its own frame. Clouds are in their LiDAR's frame; poses are named `T_parent_child`
(see `transforms`).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    # Only the type alias: importing pipeline.transforms would load scipy with every
    # `import pipeline` (and `fleetcal --help`).
    from pipeline.transforms import Matrix4


class ScanPattern(enum.StrEnum):
    """How a LiDAR's beams cover its field of view over time."""

    NON_REPETITIVE = "non_repetitive"
    """Each scan fires new directions (Livox rosette): accumulated over a stop, the points fill
    surfaces evenly, so a point sparse for its place is suspect (what stage 1 relies on)."""
    REPETITIVE = "repetitive"
    """Every scan re-fires the same directions (spinning multi-beam: Velodyne, Ouster, Hesai):
    accumulated, the points pile up along each beam, on scan lines a few degrees apart."""
    UNKNOWN = "unknown"
    """Neither the PointCloud2's fields nor its points tell (too few scans or points, or a
    recurrence of directions in between): stage 1 leaves such a LiDAR unfiltered."""


@dataclass(frozen=True)
class LidarInfo:
    """One LiDAR of the robot.

    `T_base_lidar` is the *initial* extrinsic (tf_static or config), (4, 4) float64.
    `points_per_second` is the mean rate over the recording (all scans, not only stops).
    `scan_pattern`: from its PointCloud2's beam-index field (`ring`, `channel`, `laser_id`:
    repetitive; Livox's `line`/`tag`: non-repetitive), else judged from its points
    (`pipeline.io.scan_pattern`); UNKNOWN when neither tells.
    """

    frame: str
    topic: str
    T_base_lidar: Matrix4
    scan_count: int = 0
    points_per_second: float = 0.0
    scan_pattern: ScanPattern = ScanPattern.NON_REPETITIVE


@dataclass(frozen=True)
class Stop:
    """A span where the robot stood still, with each LiDAR's scans accumulated over it.

    `t_start`, `t_end`: seconds (ROS time). `T_odom_base`: the *initial* pose of the base during
    the stop, from odometry, (4, 4). `clouds[frame]`: (N, 3) float64 points in that LiDAR's frame,
    from every scan wholly inside the stop. `scan_counts[frame]`: how many scans went in.
    `scan_sizes[frame]`: the points of each of those scans, in the order they are concatenated
    (empty where unknown: moving points are then not looked for).
    """

    index: int
    t_start: float
    t_end: float
    T_odom_base: Matrix4
    clouds: Mapping[str, NDArray[np.float64]]
    scan_counts: Mapping[str, int] = field(default_factory=dict)
    scan_sizes: Mapping[str, tuple[int, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for frame, sizes in self.scan_sizes.items():
            points = len(self.clouds.get(frame, ()))
            if sizes and sum(sizes) != points:
                raise ValueError(
                    f"stop {self.index}: the scan sizes of {frame} add up to {sum(sizes)} points, "
                    f"its cloud has {points}; a cloud filtered after reading needs its scan sizes "
                    "counted again (or left out: its moving points are then not looked for)"
                )

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


@dataclass(frozen=True)
class RecordingInfo:
    """Where a problem came from, for reports and `fleetcal inspect`."""

    path: str
    format: str
    t_start: float
    t_end: float
    message_count: int = 0
    warnings: tuple[str, ...] = ()

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start


@dataclass(frozen=True)
class CalibrationProblem:
    """Everything the four stages need: LiDARs (sorted by frame), stops, and frame names."""

    lidars: tuple[LidarInfo, ...]
    stops: tuple[Stop, ...]
    base_frame: str = "base_link"
    odom_frame: str = "odom"
    recording: RecordingInfo | None = None

    @property
    def frames(self) -> tuple[str, ...]:
        return tuple(lidar.frame for lidar in self.lidars)

    def lidar(self, frame: str) -> LidarInfo:
        for lidar in self.lidars:
            if lidar.frame == frame:
                return lidar
        raise KeyError(f"no LiDAR with frame {frame!r}; the recording has {list(self.frames)}")

    def kept_points(self) -> int:
        """Total number of points held in the stop clouds."""
        return sum(len(cloud) for stop in self.stops for cloud in stop.clouds.values())
