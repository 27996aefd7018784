"""Round trips of every format through `read_recording`, and every error the reader raises."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.io import ReaderConfig, read_recording, summarize_recording
from pipeline.io.config import PoseConfig, StopDetectionConfig
from pipeline.io.errors import (
    CorruptRecordingError,
    EmptyStopCloudError,
    MissingExtrinsicsError,
    NoPointCloudError,
    NoStopsError,
    NoTrajectoryError,
    RecordingError,
    TooFewLidarsError,
    UnknownFormatError,
)
from pipeline.io.writer import RecordingWriter, WriterFormat
from pipeline.problem import ScanPattern
from pipeline.transforms import apply, pose_difference, to_translation_xyzw
from tests.pipeline.io.conftest import SCENE
from tests.pipeline.io.recordings import Spec, Truth, write_recording

FORMATS = {
    "ros2-mcap-dir": "ros2-directory",
    "ros2-sqlite3-dir": "ros2-directory",
    "ros1": "ros1",
    "bare-mcap": "mcap",
    "bare-mcap-misnamed": "mcap",
    "bare-db3": "sqlite3",
    "ros1-misnamed": "ros1",
    "ros2-dir-without-metadata": "ros2-directory",
    "zip": "zip",
    "zip-sqlite3": "zip",
    "tar": "tar",
    "tar.gz": "tar.gz",
}


def _scans_wholly_inside(span: tuple[float, float], detected: tuple[float, float]) -> int:
    """Scans at 10 Hz from SCENE.t0 whose [stamp - 0.1, stamp + 0.1] lies in the detected span."""
    stamps = np.round(np.arange(SCENE.t0, span[1] + 1e-9, 1 / SCENE.scan_hz), 6)
    period = 1 / SCENE.scan_hz
    inside = (stamps - period >= detected[0] - 1e-6) & (stamps + period <= detected[1] + 1e-6)
    return int(inside.sum())


@pytest.mark.parametrize("name", sorted(FORMATS))
def test_every_format_reads_back_the_scene(
    name: str, recordings: dict[str, Path], truth: Truth
) -> None:
    problem = read_recording(recordings[name])

    assert problem.recording is not None and problem.recording.format == FORMATS[name]
    assert problem.frames == ("lidar_front", "lidar_rear")
    assert [lidar.topic for lidar in problem.lidars] == [
        "/lidar_front/points",
        "/lidar_rear/points",
    ]
    assert problem.base_frame == "base_link" and problem.odom_frame == "odom"
    assert len(problem.stops) == SCENE.stops
    # The rear LiDAR's scans carry a ring field: a spinning LiDAR's.
    assert [lidar.scan_pattern for lidar in problem.lidars] == [
        ScanPattern.NON_REPETITIVE,
        ScanPattern.REPETITIVE,
    ]
    for lidar in problem.lidars:
        assert lidar.scan_count == 81  # 8 s at 10 Hz, both ends included
        assert lidar.points_per_second == pytest.approx(SCENE.points * SCENE.scan_hz)
        # The chain base_link -> rear_mount -> lidar_rear is composed like tf would.
        np.testing.assert_allclose(
            lidar.T_base_lidar, truth.T_base_lidar_initial[lidar.frame], atol=1e-9
        )
    for stop, span, T_true in zip(problem.stops, truth.stop_spans, truth.T_odom_base, strict=True):
        # Detected inside the true still span, losing at most the speed window's half at each end.
        assert span[0] - 1e-6 <= stop.t_start <= span[0] + 0.15
        assert span[1] - 0.15 <= stop.t_end <= span[1] + 1e-6
        distance, angle = pose_difference(stop.T_odom_base, T_true)
        assert distance < 1e-9 and angle < 1e-4  # arccos resolves ~1e-6 deg
        expected_scans = _scans_wholly_inside(span, (stop.t_start, stop.t_end))
        for frame, cloud in stop.clouds.items():
            assert stop.scan_counts[frame] == expected_scans
            assert cloud.shape == (expected_scans * truth.valid_per_scan[frame], 3)
            assert cloud.dtype == np.float64
            # Floor points placed with the TRUE pose and extrinsic lie on z = 0 (float32 rounding).
            z = apply(T_true @ truth.T_base_lidar[frame], cloud)[:, 2]
            assert np.abs(z).max() < 1e-5
            # ... and with the perturbed initial extrinsic they do not: the check can fail.
            z_initial = apply(T_true @ truth.T_base_lidar_initial[frame], cloud)[:, 2]
            assert np.abs(z_initial).max() > 1e-2


def test_trajectory_from_tf_and_odometry_error_reach_the_stops(tmp_path: Path) -> None:
    spec = Spec(stops=2, trajectory="tf", odom_error_m=0.1, points=50)
    truth = write_recording(tmp_path / "tf", WriterFormat.ROS2_MCAP, spec)

    problem = read_recording(tmp_path / "tf")

    assert len(problem.stops) == 2
    for stop, T_odometry in zip(problem.stops, truth.T_odom_base_odometry, strict=True):
        assert pose_difference(stop.T_odom_base, T_odometry)[0] < 1e-9
    assert pose_difference(problem.stops[1].T_odom_base, truth.T_odom_base[1])[0] == pytest.approx(
        0.1
    )


def test_odometry_of_base_footprint_is_composed_with_tf_static(tmp_path: Path) -> None:
    spec = Spec(stops=2, footprint_height=0.12, points=50)
    truth = write_recording(tmp_path / "fp", WriterFormat.ROS2_MCAP, spec)

    problem = read_recording(tmp_path / "fp")

    assert "base_footprint -> base_link" in summarize_recording(tmp_path / "fp").trajectory_source
    for stop, T_true in zip(problem.stops, truth.T_odom_base, strict=True):
        assert pose_difference(stop.T_odom_base, T_true)[0] < 1e-9


def test_ros1_frames_with_leading_slash_are_normalised(tmp_path: Path) -> None:
    spec = Spec(stops=2, frame_prefix="/", points=50)
    write_recording(tmp_path / "slash.bag", WriterFormat.ROS1, spec)

    problem = read_recording(tmp_path / "slash.bag")

    assert problem.frames == ("lidar_front", "lidar_rear")
    assert problem.odom_frame == "odom"


def test_config_extrinsics_override_tf_static_and_lidar_topics_select(tmp_path: Path) -> None:
    spec = Spec(stops=2, points=50, lidars=("lidar_front", "lidar_rear"), tf_static=False)
    write_recording(tmp_path / "cfg", WriterFormat.ROS2_MCAP, spec)
    pose = PoseConfig(translation=(1.0, 2.0, 3.0), rotation_xyzw=(0.0, 0.0, 0.0, 2.0))
    config = ReaderConfig(
        extrinsics={"/lidar_front": pose, "lidar_rear": pose},
        lidar_topics=("/lidar_rear/points", "/lidar_front/points"),
    )

    problem = read_recording(tmp_path / "cfg", config)

    translation, quat = to_translation_xyzw(problem.lidar("lidar_front").T_base_lidar)
    np.testing.assert_allclose(translation, [1, 2, 3])
    np.testing.assert_allclose(quat, [0, 0, 0, 1])


def test_unknown_config_extrinsic_frame_is_a_warning(tmp_path: Path) -> None:
    write_recording(tmp_path / "w", WriterFormat.ROS2_MCAP, Spec(stops=2, points=50))
    config = ReaderConfig(extrinsics={"lidar_top": PoseConfig(translation=(0.0, 0.0, 1.0))})

    problem = read_recording(tmp_path / "w", config)

    assert problem.recording is not None
    assert any("'lidar_top', which is not a LiDAR" in w for w in problem.recording.warnings)


# -- errors -----------------------------------------------------------------------------------


def _write(tmp_path: Path, spec: Spec, fmt: WriterFormat = WriterFormat.ROS2_MCAP) -> Path:
    path = tmp_path / "rec"
    write_recording(path, fmt, spec)
    return path


def test_unknown_file_is_refused_by_its_bytes(tmp_path: Path) -> None:
    fake = tmp_path / "recording.mcap"
    fake.write_bytes(b"this is not a recording at all" * 20)
    with pytest.raises(UnknownFormatError, match=r"not a recording we can read"):
        read_recording(fake)


def test_missing_path_says_so(tmp_path: Path) -> None:
    with pytest.raises(UnknownFormatError, match=r"does not exist"):
        read_recording(tmp_path / "nope.bag")


@pytest.mark.parametrize("name", ["bare-mcap", "bare-db3", "ros1"])
def test_truncated_files_are_corrupt_with_a_remedy(
    name: str, recordings: dict[str, Path], tmp_path: Path
) -> None:
    source = recordings[name]
    cut = tmp_path / f"cut{source.suffix}"
    data = source.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(
        CorruptRecordingError, match=r"truncated or damaged: .*(copy it again|reindex)"
    ):
        read_recording(cut)


def test_truncated_archive_is_corrupt(recordings: dict[str, Path], tmp_path: Path) -> None:
    cut = tmp_path / "cut.tgz"
    data = recordings["tar.gz"].read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptRecordingError, match=r"cannot be unpacked"):
        read_recording(cut)


def test_no_pointcloud_topic(tmp_path: Path) -> None:
    with pytest.raises(
        NoPointCloudError, match=r"no sensor_msgs/PointCloud2 topic .*record each LiDAR"
    ):
        read_recording(_write(tmp_path, Spec(stops=2, lidars=())))


def test_configured_lidar_topic_missing(recordings: dict[str, Path]) -> None:
    config = ReaderConfig(lidar_topics=("/lidar_top/points", "/lidar_front/points"))
    with pytest.raises(
        NoPointCloudError, match=r"no PointCloud2 on \['/lidar_top/points'\].*fix lidar_topics"
    ):
        read_recording(recordings["bare-mcap"], config)


def test_one_lidar_is_too_few(tmp_path: Path) -> None:
    with pytest.raises(TooFewLidarsError, match=r"one LiDAR topic .*two or more LiDARs"):
        read_recording(_write(tmp_path, Spec(stops=2, points=50, lidars=("lidar_front",))))


def test_no_trajectory(tmp_path: Path) -> None:
    with pytest.raises(
        NoTrajectoryError, match=r"no trajectory: no nav_msgs/Odometry on /odom nor /tf"
    ):
        read_recording(_write(tmp_path, Spec(stops=2, points=50, trajectory="none")))


def test_odometry_topic_elsewhere_is_suggested(recordings: dict[str, Path]) -> None:
    config = ReaderConfig(odometry_topic="/wheel_odom", trajectory="odometry")
    with pytest.raises(NoTrajectoryError, match=r"Odometry on \['/odom'\]: set odometry_topic"):
        read_recording(recordings["bare-mcap"], config)


def test_trajectory_of_another_frame_without_link(recordings: dict[str, Path]) -> None:
    config = ReaderConfig(base_frame="base_footprint")
    with pytest.raises(
        NoTrajectoryError, match=r"gives poses of \['base_link'\], not of 'base_footprint'"
    ):
        read_recording(recordings["bare-mcap"], config)


def test_lidar_without_extrinsics(tmp_path: Path) -> None:
    with pytest.raises(
        MissingExtrinsicsError,
        match=r"no initial extrinsics for lidar_front .*lidar_rear.*extrinsics: ",
    ):
        read_recording(_write(tmp_path, Spec(stops=2, points=50, tf_static=False)))


def test_no_stops(tmp_path: Path) -> None:
    with pytest.raises(NoStopsError, match=r"no stops found .*longest still span lasted 0\.\d+ s"):
        read_recording(_write(tmp_path, Spec(stops=3, points=50, dwell_s=0.6)))


def test_looser_stop_settings_find_short_stops(tmp_path: Path) -> None:
    path = _write(tmp_path, Spec(stops=3, points=50, dwell_s=0.6))
    config = ReaderConfig(stops=StopDetectionConfig(min_dwell_s=0.3))
    assert len(read_recording(path, config).stops) == 3


def test_dead_lidar_has_no_valid_point_in_a_stop(tmp_path: Path) -> None:
    spec = Spec(stops=2, points=50, nan_fraction_of={"lidar_rear": 1.0})
    with pytest.raises(
        EmptyStopCloudError,
        match=r"lidar_rear .*no valid point in stop 0 .*only NaN, infinite or zero",
    ):
        read_recording(_write(tmp_path, spec))


def test_stop_shorter_than_a_scan_has_no_scan_inside(tmp_path: Path) -> None:
    spec = Spec(stops=2, points=50, scan_hz=0.5)
    with pytest.raises(EmptyStopCloudError, match=r"none of its scans lies wholly inside the stop"):
        read_recording(_write(tmp_path, spec))


def test_two_topics_in_one_frame_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "dup"
    points = np.ones((10, 3))
    with RecordingWriter(path, WriterFormat.ROS2_MCAP) as writer:
        for k in range(30):  # 3 s standing still at 10 Hz
            writer.write_pointcloud("/a/points", k * 10**8, "lidar", points)
            writer.write_pointcloud("/b/points", k * 10**8, "lidar", points)
            writer.write_odometry("/odom", k * 10**8, np.eye(4))
    with pytest.raises(RecordingError, match=r"both publish scans in frame 'lidar'"):
        read_recording(path)


def test_bag_directory_mixing_storages_is_refused(
    recordings: dict[str, Path], tmp_path: Path
) -> None:
    mixed = tmp_path / "mixed"
    shutil.copytree(recordings["ros2-dir-without-metadata"], mixed)
    shutil.copy(recordings["bare-db3"], mixed / "part_1.db3")
    with pytest.raises(CorruptRecordingError, match=r"mixes MCAP and sqlite3"):
        read_recording(mixed)


def test_ros1_bag_recorded_with_old_tf_message_type(tmp_path: Path) -> None:
    """Bags from ROS 1's `tf` package carry `tf/tfMessage`, decoded from the bag's definition."""
    from rosbags import rosbag1

    source = tmp_path / "tf2.bag"
    truth = write_recording(source, WriterFormat.ROS1, Spec(stops=2, points=50, trajectory="tf"))
    renamed = tmp_path / "tf1.bag"
    with rosbag1.Reader(source) as reader, rosbag1.Writer(renamed) as writer:
        out = {}
        for c in reader.connections:
            msgtype = "tf/msg/tfMessage" if c.msgtype == "tf2_msgs/msg/TFMessage" else c.msgtype
            out[c.id] = writer.add_connection(
                c.topic, msgtype, msgdef=c.msgdef.data, md5sum=c.digest, callerid="/rec"
            )
        for c, stamp, raw in reader.messages():
            writer.write(out[c.id], stamp, raw)

    problem = read_recording(renamed)

    assert problem.frames == ("lidar_front", "lidar_rear")
    np.testing.assert_allclose(
        problem.lidar("lidar_rear").T_base_lidar,
        truth.T_base_lidar_initial["lidar_rear"],
        atol=1e-9,
    )
    for stop, T_true in zip(problem.stops, truth.T_odom_base, strict=True):
        assert pose_difference(stop.T_odom_base, T_true)[0] < 1e-9


def test_damaged_metadata_yaml(recordings: dict[str, Path], tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(recordings["ros2-mcap-dir"], bag)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed")
    with pytest.raises(
        CorruptRecordingError, match=r"metadata.yaml cannot be read .*remove metadata"
    ):
        read_recording(bag)
