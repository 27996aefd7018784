"""Compressed recordings, as `ros2 bag record` or `rosbag record` write them, read as plain ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags import rosbag1, rosbag2
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin

from pipeline.io import read_recording
from pipeline.io.typestores import ros2_typestore
from pipeline.transforms import pose_difference
from tests.pipeline.io.recordings import Truth

Mode = CompressionMode
ROS2_VARIANTS = {
    "mcap-chunks-zstd": (StoragePlugin.MCAP, Mode.STORAGE),
    "mcap-messages-zstd": (StoragePlugin.MCAP, Mode.MESSAGE),
    "mcap-file-zstd": (StoragePlugin.MCAP, Mode.FILE),
    "sqlite3-messages-zstd": (StoragePlugin.SQLITE3, Mode.MESSAGE),
    "sqlite3-file-zstd": (StoragePlugin.SQLITE3, Mode.FILE),
}


def _rewrite_ros2(source: Path, target: Path, plugin: StoragePlugin, mode: Mode) -> Path:
    with rosbag2.Reader(source) as reader:
        writer = rosbag2.Writer(target, version=9, storage_plugin=plugin)
        writer.set_compression(mode, CompressionFormat.ZSTD)
        with writer:
            out = {
                c.id: writer.add_connection(c.topic, c.msgtype, typestore=ros2_typestore())
                for c in reader.connections
            }
            for connection, stamp, raw in reader.messages():
                writer.write(out[connection.id], stamp, raw)
    return target


def _rewrite_ros1(source: Path, target: Path, fmt: rosbag1.Writer.CompressionFormat) -> Path:
    with rosbag1.Reader(source) as reader:
        writer = rosbag1.Writer(target)
        writer.set_compression(fmt)
        with writer:
            out = {
                c.id: writer.add_connection(
                    c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest
                )
                for c in reader.connections
            }
            for connection, stamp, raw in reader.messages():
                writer.write(out[connection.id], stamp, raw)
    return target


def _same_scene(path: Path, truth: Truth) -> None:
    problem = read_recording(path)
    assert problem.frames == ("lidar_front", "lidar_rear")
    assert len(problem.stops) == len(truth.stop_spans)
    for stop, T_true in zip(problem.stops, truth.T_odom_base, strict=True):
        assert pose_difference(stop.T_odom_base, T_true)[0] < 1e-9
        assert {f: len(c) > 0 for f, c in stop.clouds.items()} == {
            "lidar_front": True,
            "lidar_rear": True,
        }
    np.testing.assert_allclose(
        problem.lidar("lidar_rear").T_base_lidar,
        truth.T_base_lidar_initial["lidar_rear"],
        atol=1e-9,
    )


@pytest.mark.parametrize("name", sorted(ROS2_VARIANTS))
def test_compressed_ros2_bags(
    name: str, recordings: dict[str, Path], truth: Truth, tmp_path: Path
) -> None:
    plugin, mode = ROS2_VARIANTS[name]
    source = recordings["ros2-mcap-dir" if plugin is StoragePlugin.MCAP else "ros2-sqlite3-dir"]
    _same_scene(_rewrite_ros2(source, tmp_path / name, plugin, mode), truth)


@pytest.mark.parametrize("fmt", list(rosbag1.Writer.CompressionFormat), ids=lambda f: f.name)
def test_compressed_ros1_bags(
    fmt: rosbag1.Writer.CompressionFormat, recordings: dict[str, Path], truth: Truth, tmp_path: Path
) -> None:
    _same_scene(_rewrite_ros1(recordings["ros1"], tmp_path / f"{fmt.name}.bag", fmt), truth)
