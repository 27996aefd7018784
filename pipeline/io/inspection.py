"""What `fleetcal inspect` reports on a recording: a JSON-ready document with warnings.

A lenient read: a LiDAR without extrinsics is a warning here (the request config may supply
them), every other problem raises the reader's typed error. Stop clouds are counted, not kept.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline.io.checks import recording_warnings
from pipeline.io.config import ReaderConfig
from pipeline.io.reader import summarize_recording
from pipeline.io.summary import RecordingSummary
from pipeline.transforms import Matrix4, to_translation_xyzw


def inspect_recording(path: Path | str, config: ReaderConfig | None = None) -> dict[str, Any]:
    """The inspection document of the recording at `path` (see `report`)."""
    config = config or ReaderConfig()
    summary = summarize_recording(path, config, keep_points=False)
    return report(summary, recording_warnings(summary, config.warnings))


def report(summary: RecordingSummary, warnings: tuple[str, ...]) -> dict[str, Any]:
    """`{"format", "lidars": [{"frame", "topic", "points", ...}], "stops": [{"start", "end",
    "duration", "scans": {frame: n}}], "base_frame", "warnings"}` plus context; times in seconds
    on the log clock, `points` = all published, a stop's `scans` = those wholly inside it.
    Clocks: `trajectory_header_offset` and each LiDAR's `header_offset` are the median
    `log time - header stamp`; a LiDAR's `clock_shift` is what was added to its stamps to put
    them on the trajectory's clock (0 unless the clocks disagree).
    """
    return {
        "path": summary.path,
        "format": summary.format,
        "storage": summary.storage,
        "start": summary.t_start_ns * 1e-9,
        "end": summary.t_end_ns * 1e-9,
        "duration": summary.duration_s,
        "messages": summary.message_count,
        "base_frame": summary.base_frame,
        "odom_frame": summary.odom_frame,
        "trajectory": summary.trajectory_source,
        "trajectory_header_offset": summary.trajectory_clock_offset_ns * 1e-9,
        "lidars": [
            {
                "frame": lidar.frame,
                "topic": lidar.topic,
                "points": lidar.points,
                "scans": lidar.scans,
                "points_per_second": lidar.points_per_second,
                "scan_pattern": str(lidar.scan_pattern),
                "scan_pattern_basis": lidar.scan_pattern_basis,
                "period": lidar.period_s,
                "header_offset": lidar.clock_offset_ns * 1e-9,
                "clock_shift": lidar.clock_shift_ns * 1e-9,
                "valid_points_in_stops": sum(
                    stop.clouds[lidar.frame].valid_points
                    for stop in summary.stops
                    if lidar.frame in stop.clouds
                ),
                "initial": _pose(lidar.T_base_lidar),
                "initial_source": lidar.extrinsic_source,
            }
            for lidar in summary.lidars
        ],
        "stops": [
            {
                "start": stop.t_start,
                "end": stop.t_end,
                "duration": stop.duration_s,
                "scans": {
                    lidar.frame: cloud.scans if (cloud := stop.clouds.get(lidar.frame)) else 0
                    for lidar in summary.lidars
                },
            }
            for stop in summary.stops
        ],
        "warnings": list(warnings),
    }


def _pose(T: Matrix4 | None) -> dict[str, list[float]] | None:
    if T is None:
        return None
    translation, quat = to_translation_xyzw(T)
    return {"translation": translation.tolist(), "rotation_xyzw": quat.tolist()}
