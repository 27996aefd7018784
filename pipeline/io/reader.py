"""Read a calibration recording into a `CalibrationProblem` (DESIGN.md's input contract).

Two passes: the first reads `/tf_static` and the trajectory (small messages), then each LiDAR's
first scans for its clock and scan period, and finds the stops; the second streams the
PointCloud2 topics once, counts every scan and decodes only the scans inside a stop. Memory
therefore holds the stop clouds, not the recording. Scans are matched to stops on the
trajectory's header clock (see `clocks`); the times reported (stops, the recording) are on the
bag's log clock, the one `ros2 bag info` shows.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from rosbags.interfaces import Connection

from pipeline.io.checks import recording_warnings, require_extrinsics, require_stop_points
from pipeline.io.clocks import NS, LidarClock, clock_notes, probe_lidar_clocks
from pipeline.io.config import ReaderConfig
from pipeline.io.errors import (
    EmptyRecordingError,
    LidarPacketsError,
    LidarTopicsError,
    NoPointCloudError,
    NoStopsError,
    TooFewLidarsError,
)
from pipeline.io.lidar_packets import packet_topics, packets_message
from pipeline.io.motion import Motion, read_motion
from pipeline.io.pointcloud import decode_xyz, field_names, point_count
from pipeline.io.scan_pattern import DirectionRecurrence, PatternJudgement, pattern_from_fields
from pipeline.io.source import (
    OpenRecording,
    connections_of,
    open_recording,
    reading_errors,
    stamp_ns,
)
from pipeline.io.stop_clouds import StopClouds
from pipeline.io.stops import StopSpan, detect_stops, still_runs
from pipeline.io.summary import LidarSummary, RecordingSummary, StopSummary
from pipeline.io.tf_tree import normalize_frame
from pipeline.io.typestores import POINTCLOUD2
from pipeline.problem import CalibrationProblem, LidarInfo, RecordingInfo, ScanPattern, Stop

# Per-point fields of radar drivers' PointCloud2s (radar cross-section, radial speed, SNR): such
# a topic is no LiDAR and is left out unless `lidar_topics` names it.
RADAR_FIELDS = (
    "rcs",
    "v_r",
    "vr",
    "snr",
    "doppler",
    "doppler_velocity",
    "radial_speed",
    "speed_radial",
    "range_rate",
)

# Scans reach the bag after their stamp; a stop is closed once the log time (on the trajectory's
# clock) is this far past it, plus the clock tolerance (latency a LiDAR's stamps may have).
_CLOSE_SLACK_NS = 2 * NS


def read_recording(path: Path | str, config: ReaderConfig | None = None) -> CalibrationProblem:
    """The `CalibrationProblem` of the recording at `path`.

    Raises a `RecordingError` subclass whose message says what is wrong and what to do: unknown,
    corrupt or truncated file, no PointCloud2, fewer than two LiDARs, no trajectory, no stops, a
    LiDAR without extrinsics, or a LiDAR without valid points in a stop.
    """
    config = config or ReaderConfig()
    summary = summarize_recording(path, config, keep_points=True)
    require_extrinsics(summary)
    lidars = tuple(
        LidarInfo(
            lidar.frame,
            lidar.topic,
            lidar.T_base_lidar,
            lidar.scans,
            lidar.points_per_second,
            lidar.scan_pattern,
        )
        for lidar in summary.lidars
        if lidar.T_base_lidar is not None
    )
    stops = tuple(
        Stop(
            index=stop.index,
            t_start=stop.t_start,
            t_end=stop.t_end,
            T_odom_base=stop.T_odom_base,
            clouds=MappingProxyType(
                {f: c.points for f, c in stop.clouds.items() if c.points is not None}
            ),
            scan_counts=MappingProxyType({f: c.scans for f, c in stop.clouds.items()}),
            scan_sizes=MappingProxyType({f: c.scan_sizes for f, c in stop.clouds.items()}),
        )
        for stop in summary.stops
    )
    info = RecordingInfo(
        path=summary.path,
        format=summary.format,
        t_start=summary.t_start_ns * 1e-9,
        t_end=summary.t_end_ns * 1e-9,
        message_count=summary.message_count,
        warnings=recording_warnings(summary, config.warnings),
    )
    return CalibrationProblem(lidars, stops, summary.base_frame, summary.odom_frame, info)


def summarize_recording(
    path: Path | str, config: ReaderConfig | None = None, *, keep_points: bool = True
) -> RecordingSummary:
    """Read the recording once (two passes) without judging extrinsics; `inspect` stops here.

    With `keep_points=False` the stop clouds are counted, not kept. Raises every `RecordingError`
    of `read_recording` except the one for missing extrinsics.
    """
    config = config or ReaderConfig()
    with open_recording(
        Path(path), limits=config.archive, scratch_dir=config.scratch_dir
    ) as opened:
        reading = _read(opened, config, keep_points)
    summary = _summary(str(path), reading, config)
    require_stop_points(summary)
    return summary


@dataclass(frozen=True)
class _Reading:
    """What the passes over one open recording found, before it is summarised."""

    opened: OpenRecording
    motion: Motion
    clocks: dict[str, LidarClock]
    stops: tuple[StopSpan, ...]
    clouds: StopClouds
    lidar_stats: dict[str, _TopicStats]
    topic_notes: list[str]
    t_start_ns: int
    t_end_ns: int
    message_count: int


def _read(opened: OpenRecording, config: ReaderConfig, keep_points: bool) -> _Reading:
    """The trajectory, the LiDARs' clocks, the stops, then the stop clouds (the second pass)."""
    topics, topic_notes = _lidar_topics(opened, config.lidar_topics)
    motion = read_motion(
        opened,
        trajectory=config.trajectory,
        odometry_topic=config.odometry_topic,
        odom_frame=normalize_frame(config.odom_frame),
        base_frame=normalize_frame(config.base_frame),
    )
    clocks = probe_lidar_clocks(
        opened, topics, motion.clock, tolerance_ns=round(config.clock_tolerance_s * NS)
    )
    stops = _stops(opened, motion, clocks, config)
    clouds, lidar_stats, radars = _read_clouds(
        opened, topics, stops, clocks, motion, config, keep_points
    )
    topic_notes += [
        f"{topic} left out: its fields {', '.join(fields)} are a radar's, not a LiDAR's; "
        "to read it as a LiDAR, list the LiDAR topics in reader.lidar_topics"
        for topic, fields in radars.items()
    ]
    return _Reading(
        opened,
        motion,
        clocks,
        stops,
        clouds,
        lidar_stats,
        topic_notes,
        opened.start_time,
        opened.end_time,
        opened.message_count,
    )


def _summary(path: str, reading: _Reading, config: ReaderConfig) -> RecordingSummary:
    opened, motion, clocks, clouds = reading.opened, reading.motion, reading.clocks, reading.clouds
    lidars, notes = _lidars(
        opened, reading.lidar_stats, clouds, clocks, motion, config, reading.topic_notes
    )
    to_log = motion.clock.offset_ns  # stops are reported on the log clock
    return RecordingSummary(
        path=path,
        format=opened.format.value,
        storage=opened.storage.value,
        t_start_ns=reading.t_start_ns,
        t_end_ns=reading.t_end_ns,
        message_count=reading.message_count,
        trajectory_source=motion.trajectory.source,
        trajectory_clock_offset_ns=to_log,
        odom_frame=motion.odom_frame,
        base_frame=normalize_frame(config.base_frame),
        lidars=lidars,
        stops=tuple(
            StopSummary(
                k,
                stop.t_start_ns + to_log,
                stop.t_end_ns + to_log,
                stop.T_odom_base,
                MappingProxyType(clouds.closed[k]),
            )
            for k, stop in enumerate(reading.stops)
        ),
        notes=(
            *reading.topic_notes,
            *motion.notes,
            *clock_notes(motion.trajectory.source, motion.clock, clocks.values()),
            *notes,
        ),
    )


@dataclass
class _TopicStats:
    topic: str
    frame: str = ""
    scans: int = 0
    points: int = 0
    first_ns: int = 0
    last_ns: int = 0
    from_fields: PatternJudgement | None = None
    directions: DirectionRecurrence | None = None
    """Set when the fields tell no pattern: the first scans are then judged by their points."""

    def start(self, fields: tuple[str, ...]) -> None:
        """The topic's first scan: its fields tell the pattern, or its points will."""
        self.from_fields = pattern_from_fields(fields)
        if self.from_fields is None:
            self.directions = DirectionRecurrence()

    @property
    def wants_points(self) -> bool:
        return self.directions is not None and self.directions.wants_more

    @property
    def pattern(self) -> PatternJudgement:
        if self.from_fields is not None:
            return self.from_fields
        assert self.directions is not None, "pattern asked before the topic's first scan"
        return self.directions.judge()

    def add(self, frame: str, stamp: int, points: int, path: Path) -> None:
        if self.scans and frame != self.frame:
            raise LidarTopicsError(
                f"{path}: {self.topic} carries scans of two frames ({self.frame!r}, then "
                f"{frame!r}); publish each LiDAR on its own topic with one frame_id"
            )
        if not self.scans:
            self.frame, self.first_ns = frame, stamp
        self.scans += 1
        self.points += points
        self.first_ns, self.last_ns = min(self.first_ns, stamp), max(self.last_ns, stamp)


def _lidar_topics(
    opened: OpenRecording, wanted: tuple[str, ...]
) -> tuple[dict[str, list[Connection]], list[str]]:
    """The PointCloud2 topics to read as LiDARs, and notes on those left out."""
    if opened.message_count == 0:
        topics = sorted({c.topic for c in opened.connections})
        raise EmptyRecordingError(
            f"{opened.path} is empty: it holds no message (topics declared: {topics or 'none'}); "
            "the recorder stopped before anything was published. Record the routine again"
        )
    clouds = connections_of(opened, POINTCLOUD2)
    notes = []
    if wanted:
        missing = [topic for topic in wanted if topic not in clouds]
        if missing:
            raise NoPointCloudError(
                f"{opened.path} has no PointCloud2 on {missing} (its PointCloud2 topics: "
                f"{sorted(clouds) or 'none'}); fix lidar_topics in the config"
            )
        unnamed = sorted(set(clouds) - set(wanted))
        if unnamed:
            notes.append(
                f"PointCloud2 topics left out: {', '.join(unnamed)} (reader.lidar_topics names "
                f"only {', '.join(wanted)}); add them to reader.lidar_topics to calibrate them too"
            )
        clouds = {topic: clouds[topic] for topic in wanted}
    if not clouds:
        packets = packet_topics((c.topic, c.msgtype) for c in opened.connections)
        if packets:
            raise LidarPacketsError(packets_message(str(opened.path), packets))
        others = sorted({c.topic for c in opened.connections})
        raise NoPointCloudError(
            f"{opened.path} has no sensor_msgs/PointCloud2 topic (topics: {others or 'none'}); "
            "record each LiDAR's point cloud, one PointCloud2 topic per LiDAR"
        )
    if len(clouds) < 2:
        raise TooFewLidarsError(
            f"{opened.path} has one LiDAR topic ({next(iter(clouds))}); calibration needs two or "
            "more LiDARs, each on its own PointCloud2 topic"
        )
    return dict(clouds), notes


def _stops(
    opened: OpenRecording, motion: Motion, clocks: dict[str, LidarClock], config: ReaderConfig
) -> tuple[StopSpan, ...]:
    settings = config.stops.model_dump(exclude={"min_dwell_s", "min_scan_periods"})
    slowest = max(clocks.values(), key=lambda clock: clock.period_ns, default=None)
    min_dwell_s, why = config.stops.min_dwell_s, "min_dwell_s"
    if slowest is not None and config.stops.min_scan_periods * slowest.period_ns / NS > min_dwell_s:
        min_dwell_s = config.stops.min_scan_periods * slowest.period_ns / NS
        why = (
            f"{config.stops.min_scan_periods:g} scan periods of {slowest.topic} "
            f"({slowest.period_ns / NS:.3f} s each; min_dwell_s is {config.stops.min_dwell_s} s)"
        )
    stops = detect_stops(motion.trajectory, min_dwell_s=min_dwell_s, **settings)
    if stops:
        return stops
    runs = still_runs(motion.trajectory, **settings)
    longest = float(runs.durations_s.max()) if len(runs.durations_s) else 0.0
    raise NoStopsError(
        f"{opened.path}: no stops found in the trajectory ({motion.trajectory.source}, "
        f"{len(motion.trajectory)} poses): the robot never stood still (under "
        f"{config.stops.max_linear_speed} m/s and {config.stops.max_angular_speed_deg} deg/s) for "
        f"{min_dwell_s:.2f} s ({why}); its longest still span lasted {longest:.2f} s. Record a "
        "stop-and-go routine, or loosen the stops settings of the reader config"
    )


def _read_clouds(
    opened: OpenRecording,
    topics: dict[str, list[Connection]],
    stops: tuple[StopSpan, ...],
    clocks: dict[str, LidarClock],
    motion: Motion,
    config: ReaderConfig,
    keep_points: bool,
) -> tuple[StopClouds, dict[str, _TopicStats], dict[str, tuple[str, ...]]]:
    """Stream the LiDAR topics once: stop clouds, per-topic counts and scan patterns, and the
    topics left out as radars (their radar fields) when `lidar_topics` does not name them."""
    clouds = StopClouds(stops, keep_points=keep_points)
    slack_ns = _CLOSE_SLACK_NS + round(config.clock_tolerance_s * NS)
    stats = {topic: _TopicStats(topic) for topic in topics}
    radars: dict[str, tuple[str, ...]] = {}
    frame_topic: dict[str, str] = {}
    connections = [c for group in topics.values() for c in group]
    with reading_errors(opened.path, opened.storage):
        for connection, log_ns, raw in opened.messages(connections):
            topic = connection.topic
            if topic in radars:
                continue
            msg: Any = opened.deserialize(raw, connection)
            topic_stats = stats[topic]
            if not topic_stats.scans:
                fields = field_names(msg)
                radar = tuple(name for name in fields if name in RADAR_FIELDS)
                if radar and not config.lidar_topics:
                    radars[topic] = radar
                    continue
                topic_stats.start(fields)
            frame = normalize_frame(msg.header.frame_id)
            if frame_topic.setdefault(frame, topic) != topic:
                raise LidarTopicsError(
                    f"{opened.path}: {frame_topic[frame]} and {topic} both publish scans in "
                    f"frame {frame!r}. Each LiDAR needs its own frame_id; if one topic is the "
                    "LiDAR and the other is derived from it (filtered, cropped), name the LiDAR "
                    f"topics in reader.lidar_topics (e.g. [{frame_topic[frame]}, ...])"
                )
            if not frame:
                raise LidarTopicsError(
                    f"{opened.path}: scans on {topic} have an empty header.frame_id; name each "
                    "LiDAR's frame"
                )
            stamp = clocks[topic].on_trajectory_clock(stamp_ns(msg.header), log_ns)
            topic_stats.add(frame, stamp, point_count(msg), opened.path)
            points = None
            if clouds.stop_index(stamp) is not None or topic_stats.wants_points:
                points = decode_xyz(
                    msg, topic, drop_zero_points=config.drop_zero_points, dtype=None
                )
                if topic_stats.directions is not None:
                    topic_stats.directions.add(points)
            clouds.add_scan(frame, stamp, points)
            clouds.close_before(log_ns - motion.clock.offset_ns - slack_ns)
    clouds.close_all()
    return clouds, {t: s for t, s in stats.items() if t not in radars}, radars


def _lidars(
    opened: OpenRecording,
    stats: dict[str, _TopicStats],
    clouds: StopClouds,
    clocks: dict[str, LidarClock],
    motion: Motion,
    config: ReaderConfig,
    left_out: list[str],
) -> tuple[tuple[LidarSummary, ...], list[str]]:
    """One summary per LiDAR topic with scans, and notes (`left_out`: on topics not read)."""
    notes = [f"{topic} has no scans and was ignored" for topic, s in stats.items() if not s.scans]
    notes += [
        f"{count} scans of {frame} reached the recording more than "
        f"{_CLOSE_SLACK_NS / NS + config.clock_tolerance_s:g} s after their stamps, when their "
        "stop was closed, and were left out of it; check the LiDAR's stamps"
        for frame, count in sorted(clouds.late.items())
    ]
    present = sorted((s for s in stats.values() if s.scans), key=lambda s: s.frame)
    if len(present) < 2:
        raise TooFewLidarsError(
            f"{opened.path} has scans from {len(present)} LiDAR(s) "
            f"({[s.topic for s in present]}); calibration needs two or more"
            + "".join(f"; {note}" for note in left_out)
        )
    overrides = {normalize_frame(f): pose.matrix() for f, pose in config.extrinsics.items()}
    frames = [s.frame for s in present]
    notes += [
        f"the config gives extrinsics for {f!r}, which is not a LiDAR here (LiDARs: {frames})"
        for f in sorted(set(overrides) - set(frames))
    ]
    base = normalize_frame(config.base_frame)
    lidars = []
    for s in present:
        pattern = s.pattern
        if pattern.pattern is ScanPattern.UNKNOWN:
            notes.append(
                f"LiDAR {s.frame} ({s.topic}): scan pattern unknown ({pattern.basis}); stage 1 "
                "leaves its clouds unfiltered. If you know it, set it in the pipeline config: "
                f"denoise.scan_patterns: {{{s.frame}: repetitive}} (or non_repetitive)"
            )
        T, source = overrides.get(s.frame), "config"
        if T is None:
            T, source = motion.tree.lookup(base, s.frame), "tf_static"
        lidars.append(
            LidarSummary(
                frame=s.frame,
                topic=s.topic,
                scans=s.scans,
                points=s.points,
                duration_s=(s.last_ns - s.first_ns) * 1e-9,
                period_s=clouds.period_ns(s.frame) * 1e-9,
                T_base_lidar=None if T is None else np.asarray(T, dtype=np.float64),
                extrinsic_source=None if T is None else source,
                scan_pattern=pattern.pattern,
                scan_pattern_basis=pattern.basis,
                clock_offset_ns=clocks[s.topic].clock.offset_ns,
                clock_shift_ns=clocks[s.topic].shift_ns,
            )
        )
    return tuple(lidars), notes
