"""`RecordingWriter`'s header clock: header stamps on another clock than the bag's log times."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.io.errors import RecordingError
from pipeline.io.source import open_recording, stamp_ns
from pipeline.io.writer import RecordingWriter, WriterFormat

NS = 1_000_000_000
WALL_NS = 1_700_000_000 * NS


def _write(path: Path, fmt: WriterFormat, offset: int | dict[str, int]) -> None:
    with RecordingWriter(path, fmt, header_clock_offset_ns=offset) as writer:
        writer.write_transforms(WALL_NS, [("base_link", "lidar", np.eye(4))], static=True)
        writer.write_pointcloud("/lidar/points", WALL_NS + 1, "lidar", np.zeros((3, 3)))
        writer.write_odometry("/odom", WALL_NS + 2, np.eye(4))
        writer.write_transforms(WALL_NS + 3, [("odom", "base_link", np.eye(4))])


def _stamps(path: Path) -> dict[str, tuple[int, int]]:
    """`topic: (log time, header stamp)` of the one message on each topic."""
    found = {}
    with open_recording(path) as opened:
        for connection, log_ns, raw in opened.messages(opened.connections):
            msg: Any = opened.deserialize(raw, connection)
            header = msg.transforms[0].header if hasattr(msg, "transforms") else msg.header
            found[connection.topic] = (log_ns, stamp_ns(header))
    return found


@pytest.mark.parametrize("fmt", [WriterFormat.ROS2_MCAP, WriterFormat.ROS1])
def test_one_offset_moves_every_header_onto_simulated_time(
    tmp_path: Path, fmt: WriterFormat
) -> None:
    _write(tmp_path / "sim", fmt, -(WALL_NS - 1000 * NS))

    stamps = _stamps(tmp_path / "sim")

    assert stamps == {
        "/tf_static": (WALL_NS, 1000 * NS),
        "/lidar/points": (WALL_NS + 1, 1000 * NS + 1),
        "/odom": (WALL_NS + 2, 1000 * NS + 2),
        "/tf": (WALL_NS + 3, 1000 * NS + 3),
    }


def test_by_topic_offsets_leave_other_topics_on_the_log_time(tmp_path: Path) -> None:
    behind = -120 * 86_400 * NS  # a LiDAR clock four months behind
    _write(tmp_path / "r", WriterFormat.ROS2_MCAP, {"/lidar/points": behind})

    stamps = _stamps(tmp_path / "r")

    assert stamps["/lidar/points"] == (WALL_NS + 1, WALL_NS + 1 + behind)
    assert stamps["/odom"] == (WALL_NS + 2, WALL_NS + 2)
    assert stamps["/tf"] == (WALL_NS + 3, WALL_NS + 3)


def test_default_header_stamps_equal_the_log_times(tmp_path: Path) -> None:
    _write(tmp_path / "r", WriterFormat.ROS2_SQLITE3, 0)
    assert all(log == header for log, header in _stamps(tmp_path / "r").values())


def test_offset_before_time_zero_is_refused(tmp_path: Path) -> None:
    with (
        pytest.raises(RecordingError, match=r"puts /lidar/points's header stamp before 0"),
        RecordingWriter(tmp_path / "r", header_clock_offset_ns=-2 * NS) as writer,
    ):
        writer.write_pointcloud("/lidar/points", NS, "lidar", np.zeros((3, 3)))
