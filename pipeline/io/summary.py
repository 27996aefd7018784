"""What one read of a recording found, before it is judged: the strict reader turns it into a
`CalibrationProblem`, `fleetcal inspect` into a report with warnings.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from pipeline.io.stop_clouds import StopCloud
from pipeline.problem import ScanPattern
from pipeline.transforms import Matrix4


@dataclass(frozen=True)
class LidarSummary:
    """A LiDAR topic: its frame, scan and point counts (all scans), and initial extrinsic if any.

    `points` counts every point published (`width * height`, valid or not); `period_s` is the
    median spacing of its scan stamps. `extrinsic_source` is `config`, `tf_static` or None.
    `scan_pattern`: from its first scan's fields, else from its first scans' points
    (`scan_pattern`); `scan_pattern_basis` says which, in words.
    `clock_offset_ns`: median `log time - header stamp` of its scans; `clock_shift_ns`: what was
    added to its stamps to put them on the trajectory's clock (0 unless the clocks disagree).
    """

    frame: str
    topic: str
    scans: int
    points: int
    duration_s: float
    period_s: float
    T_base_lidar: Matrix4 | None
    extrinsic_source: str | None
    scan_pattern: ScanPattern = ScanPattern.NON_REPETITIVE
    scan_pattern_basis: str = ""
    clock_offset_ns: int = 0
    clock_shift_ns: int = 0

    @property
    def points_per_second(self) -> float:
        span = self.duration_s + self.period_s
        return self.points / span if span > 0 else 0.0


@dataclass(frozen=True)
class StopSummary:
    """A stop: its span (ns, on the log clock), mean initial `T_odom_base` (4, 4), and each
    LiDAR's cloud."""

    index: int
    t_start_ns: int
    t_end_ns: int
    T_odom_base: Matrix4
    clouds: Mapping[str, StopCloud]

    @property
    def t_start(self) -> float:
        return self.t_start_ns * 1e-9

    @property
    def t_end(self) -> float:
        return self.t_end_ns * 1e-9

    @property
    def duration_s(self) -> float:
        return (self.t_end_ns - self.t_start_ns) * 1e-9


@dataclass(frozen=True)
class RecordingSummary:
    """Everything read from one recording. LiDARs sorted by frame; stops in time order.

    `format` is what the user gave (e.g. `zip`), `storage` what was inside (`mcap`, `sqlite3`,
    `ros1`). `notes` are things noticed while reading that the user should hear about.
    `trajectory_clock_offset_ns`: median `log time - header stamp` of the trajectory; stops are
    found on its header clock and reported on the log clock, shifted by this.
    """

    path: str
    format: str
    storage: str
    t_start_ns: int
    t_end_ns: int
    message_count: int
    trajectory_source: str
    odom_frame: str
    base_frame: str
    lidars: tuple[LidarSummary, ...]
    stops: tuple[StopSummary, ...]
    notes: tuple[str, ...] = ()
    trajectory_clock_offset_ns: int = 0

    @property
    def duration_s(self) -> float:
        return (self.t_end_ns - self.t_start_ns) * 1e-9
