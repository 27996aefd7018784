"""The calibrated copy of a recording reads back (through `read_recording`) with the calibrated
extrinsics, the static tree's shape, and every other message unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.interfaces import ConnectionExtRosbag1, ConnectionExtRosbag2, QosDurability

from pipeline.io import read_recording
from pipeline.io.errors import CorruptRecordingError, RecordingError
from pipeline.io.retag import write_calibrated_recording
from pipeline.io.source import open_recording
from pipeline.io.writer import WriterFormat
from pipeline.transforms import from_xyz_rpy, invert
from tests.pipeline.io.recordings import T_BASE_MOUNT, TRUE_EXTRINSICS, Spec, write_recording

TOLERANCE = 1e-9
# A "calibration" that differs from both the truth and the recording's tf_static.
CALIBRATED = {
    "lidar_front": TRUE_EXTRINSICS["lidar_front"] @ from_xyz_rpy([0.001, 0, 0], [0, 0, 1e-3]),
    "lidar_rear": TRUE_EXTRINSICS["lidar_rear"] @ from_xyz_rpy([0, -0.002, 0.003], [2e-3, 0, 0]),
}


@pytest.mark.parametrize("name", ["ros2-mcap-dir", "ros2-sqlite3-dir", "ros1", "zip", "bare-db3"])
def test_the_copy_reads_back_with_the_calibrated_extrinsics(
    recordings: dict[str, Path], tmp_path: Path, name: str
) -> None:
    source = read_recording(recordings[name])
    written = write_calibrated_recording(recordings[name], tmp_path / "calibrated", CALIBRATED)

    copy = read_recording(written.path)
    for frame, T in CALIBRATED.items():
        np.testing.assert_allclose(copy.lidar(frame).T_base_lidar, T, rtol=0, atol=TOLERANCE)
    # Everything else is the same recording: same stops, same clouds, same trajectory.
    assert len(copy.stops) == len(source.stops)
    for ours, theirs in zip(copy.stops, source.stops, strict=True):
        np.testing.assert_array_equal(ours.T_odom_base, theirs.T_odom_base)
        for frame, cloud in theirs.clouds.items():
            np.testing.assert_array_equal(ours.clouds[frame], cloud)
    assert source.recording is not None
    assert written.messages == source.recording.message_count - written.replaced_messages + 1
    assert written.format == ("ros1" if name == "ros1" else "ros2-mcap")


def test_a_lidar_under_a_mount_frame_stays_under_it(
    recordings: dict[str, Path], tmp_path: Path
) -> None:
    written = write_calibrated_recording(
        recordings["ros2-mcap-dir"], tmp_path / "calibrated", CALIBRATED
    )
    edges = {(e.parent, e.child): e.T_parent_child for e in written.edges}
    assert sorted(edges) == [
        ("base_link", "lidar_front"),
        ("base_link", "rear_mount"),
        ("rear_mount", "lidar_rear"),
    ]
    np.testing.assert_array_equal(edges[("base_link", "rear_mount")], T_BASE_MOUNT)
    np.testing.assert_allclose(
        T_BASE_MOUNT @ edges[("rear_mount", "lidar_rear")],
        CALIBRATED["lidar_rear"],
        rtol=0,
        atol=TOLERANCE,
    )


@pytest.mark.parametrize("name", ["ros2-mcap-dir", "ros1"])
def test_one_latched_tf_static_message_replaces_the_old_ones(
    recordings: dict[str, Path], tmp_path: Path, name: str
) -> None:
    written = write_calibrated_recording(recordings[name], tmp_path / "calibrated", CALIBRATED)
    with open_recording(written.path) as opened:
        static = [c for c in opened.connections if c.topic == "/tf_static"]
        assert [c.msgcount for c in static] == [1]
        ext = static[0].ext
        if isinstance(ext, ConnectionExtRosbag2):
            assert [q.durability for q in ext.offered_qos_profiles] == [
                QosDurability.TRANSIENT_LOCAL
            ]
        else:
            assert isinstance(ext, ConnectionExtRosbag1)
            assert ext.latching == 1
        # The static tree is known from the first message on.
        first = next(opened.messages(static))
        assert first[1] == opened.start_time
        message = opened.deserialize(first[2], static[0])
        assert {t.child_frame_id for t in message.transforms} == {
            "lidar_front",
            "rear_mount",
            "lidar_rear",
        }


def test_lidars_without_tf_static_hang_from_the_base(tmp_path: Path) -> None:
    """A recording whose extrinsics came from the config gets them in its copy's /tf_static."""
    source = tmp_path / "no_tf"
    write_recording(source, WriterFormat.ROS2_MCAP, Spec(stops=2, tf_static=False))
    written = write_calibrated_recording(source, tmp_path / "calibrated", CALIBRATED)
    assert sorted((e.parent, e.child) for e in written.edges) == [
        ("base_link", "lidar_front"),
        ("base_link", "lidar_rear"),
    ]
    copy = read_recording(written.path)
    np.testing.assert_allclose(
        copy.lidar("lidar_rear").T_base_lidar, CALIBRATED["lidar_rear"], rtol=0, atol=TOLERANCE
    )


def test_a_lidar_mounted_on_another_lidar_composes_with_its_calibrated_parent(
    tmp_path: Path,
) -> None:
    """Ancestors are re-expressed first: the rear LiDAR's edge uses the calibrated front pose."""
    from pipeline.io.retag import StaticEdge, calibrated_static_edges

    T_front_rear = invert(TRUE_EXTRINSICS["lidar_front"]) @ TRUE_EXTRINSICS["lidar_rear"]
    original = [
        StaticEdge("base_link", "lidar_front", TRUE_EXTRINSICS["lidar_front"]),
        StaticEdge("lidar_front", "lidar_rear", T_front_rear),
    ]
    edges = {
        (e.parent, e.child): e.T_parent_child
        for e in calibrated_static_edges(original, CALIBRATED, "base_link")
    }
    np.testing.assert_allclose(
        edges[("base_link", "lidar_front")] @ edges[("lidar_front", "lidar_rear")],
        CALIBRATED["lidar_rear"],
        rtol=0,
        atol=TOLERANCE,
    )


def test_an_existing_destination_is_refused(recordings: dict[str, Path], tmp_path: Path) -> None:
    (tmp_path / "calibrated").mkdir()
    with pytest.raises(RecordingError, match="already exists; choose a new output path"):
        write_calibrated_recording(recordings["ros1"], tmp_path / "calibrated", CALIBRATED)


def test_a_truncated_source_is_reported(recordings: dict[str, Path], tmp_path: Path) -> None:
    data = recordings["ros1"].read_bytes()
    broken = tmp_path / "broken.bag"
    broken.write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptRecordingError, match="truncated or damaged"):
        write_calibrated_recording(broken, tmp_path / "calibrated.bag", CALIBRATED)
