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
from pipeline.problem import CalibrationProblem, ScanPattern
from pipeline.transforms import apply, from_xyz_rpy, pose_difference, to_translation_xyzw
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
            # Each scan's valid points, in the order they are concatenated (moving points).
            assert stop.scan_sizes[frame] == (truth.valid_per_scan[frame],) * expected_scans
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
    with pytest.raises(
        NoStopsError,
        match=r"no stops found .*for 0\.30 s \(min_dwell_s\); its longest still span "
        r"lasted 0\.20 s",
    ):
        read_recording(_write(tmp_path, Spec(stops=3, points=50, dwell_s=0.2)))


def test_looser_stop_settings_find_shorter_stops(tmp_path: Path) -> None:
    path = _write(tmp_path, Spec(stops=3, points=50, dwell_s=0.2, scan_hz=20.0))
    config = ReaderConfig(stops=StopDetectionConfig(min_dwell_s=0.15))
    problem = read_recording(path, config)
    assert [stop.scan_counts["lidar_front"] for stop in problem.stops] == [3, 3, 3]


@pytest.mark.parametrize(
    ("dwell_s", "scans"),
    [(0.3, 2), (0.4, 3), (0.8, 7), (1.0, 9)],
)
def test_short_stops_are_kept_by_default_with_their_scans(
    tmp_path: Path, dwell_s: float, scans: int
) -> None:
    spec = Spec(stops=4, points=50, dwell_s=dwell_s, t0=1_700_000_000.0)
    truth = write_recording(tmp_path / "r", WriterFormat.ROS2_MCAP, spec)

    problem = read_recording(tmp_path / "r")

    assert len(problem.stops) == 4
    for stop, (start, end) in zip(problem.stops, truth.stop_spans, strict=True):
        # The span is the true still span, to the trajectory's float-second stamps' rounding.
        assert stop.t_start == pytest.approx(start, abs=1e-5)
        assert stop.t_end == pytest.approx(end, abs=1e-5)
        assert dict(stop.scan_counts) == {"lidar_front": scans, "lidar_rear": scans}


def test_stops_lasting_exactly_the_configured_minimum_are_all_found(tmp_path: Path) -> None:
    path = _write(tmp_path, Spec(stops=5, points=50, dwell_s=1.0, t0=1_700_000_000.0))
    config = ReaderConfig(stops=StopDetectionConfig(min_dwell_s=1.0))
    assert len(read_recording(path, config).stops) == 5


def test_stops_shorter_than_three_scan_periods_are_no_stops(tmp_path: Path) -> None:
    path = _write(tmp_path, Spec(stops=3, points=50, dwell_s=1.0, scan_hz=2.5))
    with pytest.raises(
        NoStopsError,
        match=r"for 1\.20 s \(3 scan periods of /lidar_front/points \(0\.400 s each; "
        r"min_dwell_s is 0\.3 s\)\); its longest still span lasted 1\.00 s",
    ):
        read_recording(path)
    assert (
        len(
            read_recording(
                _write(tmp_path / "b", Spec(stops=3, points=50, dwell_s=1.2, scan_hz=2.5))
            ).stops
        )
        == 3
    )


def test_dead_lidar_has_no_valid_point_in_a_stop(tmp_path: Path) -> None:
    spec = Spec(stops=2, points=50, nan_fraction_of={"lidar_rear": 1.0})
    with pytest.raises(
        EmptyStopCloudError,
        match=r"lidar_rear .*no valid point in stop 0 .*only NaN, infinite or zero",
    ):
        read_recording(_write(tmp_path, spec))


def test_lidar_silent_during_a_stop_has_no_scan_inside(tmp_path: Path) -> None:
    path = tmp_path / "silent"
    points = np.ones((10, 3))
    with RecordingWriter(path, WriterFormat.ROS2_MCAP) as writer:
        writer.write_transforms(
            0, [("base_link", "a", np.eye(4)), ("base_link", "b", np.eye(4))], static=True
        )
        for k in range(51):  # still 0-2 s, a 0.5 m drive, still 3-5 s; b is silent after 2.5 s
            t = k * 10**8
            writer.write_odometry(
                "/odom", t, from_xyz_rpy([0.5 * min(max(t / 1e9 - 2, 0), 1), 0, 0], [0, 0, 0])
            )
            writer.write_pointcloud("/a/points", t, "a", points)
            if t < 25 * 10**8:
                writer.write_pointcloud("/b/points", t, "b", points)
    with pytest.raises(
        EmptyStopCloudError,
        match=r"LiDAR b \(/b/points\) has no valid point in stop 1 .*none of its scans lies "
        r"wholly inside the stop \(0 stamped in it",
    ):
        read_recording(path)


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


# -- clocks -----------------------------------------------------------------------------------

NS = 1_000_000_000
WALL_T0 = 1_700_000_000.0  # the wall clock `ros2 bag record` logs
WALL_T0_NS = round(WALL_T0 * NS)
MONTHS_NS = 120 * 86_400 * NS
LIDAR_TOPICS = ("/lidar_front/points", "/lidar_rear/points")


def _clock_twin(
    tmp_path: Path,
    name: str,
    offset: int | dict[str, int] = 0,
    fmt: WriterFormat = WriterFormat.ROS2_MCAP,
    trajectory: str = "odometry",
) -> Path:
    """The same routine (stops of 0.8 s) on the same log times, headers `offset` from them."""
    spec = Spec(
        stops=3,
        points=60,
        dwell_s=0.8,
        t0=WALL_T0,
        trajectory=trajectory,  # type: ignore[arg-type]
        header_clock_offset_ns=offset,
    )
    write_recording(tmp_path / name, fmt, spec)
    return tmp_path / name


def assert_same_problem(a: CalibrationProblem, b: CalibrationProblem) -> None:
    """Bit for bit, but for the file's path and the warnings (checked by the caller)."""
    assert (a.frames, a.base_frame, a.odom_frame) == (b.frames, b.base_frame, b.odom_frame)
    for x, y in zip(a.lidars, b.lidars, strict=True):
        assert (x.topic, x.scan_count, x.points_per_second, x.scan_pattern) == (
            y.topic,
            y.scan_count,
            y.points_per_second,
            y.scan_pattern,
        )
        assert x.T_base_lidar.tobytes() == y.T_base_lidar.tobytes()
    assert len(a.stops) == len(b.stops) == 3
    for s, t in zip(a.stops, b.stops, strict=True):
        assert (s.index, s.t_start, s.t_end) == (t.index, t.t_start, t.t_end)
        assert dict(s.scan_counts) == dict(t.scan_counts) == {"lidar_front": 7, "lidar_rear": 7}
        assert s.T_odom_base.tobytes() == t.T_odom_base.tobytes()
        assert s.clouds.keys() == t.clouds.keys()
        for frame, cloud in s.clouds.items():
            assert cloud.dtype == t.clouds[frame].dtype
            assert cloud.tobytes() == t.clouds[frame].tobytes()
    assert a.recording is not None and b.recording is not None
    assert (a.recording.format, a.recording.t_start, a.recording.t_end) == (
        b.recording.format,
        b.recording.t_start,
        b.recording.t_end,
    )


@pytest.mark.parametrize(
    ("sim_start_s", "trajectory", "fmt"),
    [
        (0, "odometry", WriterFormat.ROS2_MCAP),  # stamps of exactly 0 are time, not unset
        (1000, "tf", WriterFormat.ROS2_MCAP),
        (1000, "odometry", WriterFormat.ROS1),
    ],
)
def test_simulated_clock_reads_like_its_wall_clock_twin(
    tmp_path: Path, sim_start_s: int, trajectory: str, fmt: WriterFormat
) -> None:
    """Gazebo / Isaac: every header on simulated time, the bag's log times on the wall clock."""
    wall = _clock_twin(tmp_path, "wall", 0, fmt, trajectory)
    sim = _clock_twin(tmp_path, "sim", sim_start_s * NS - WALL_T0_NS, fmt, trajectory)

    problem = read_recording(sim)
    twin = read_recording(wall)

    assert_same_problem(problem, twin)
    assert problem.recording is not None and twin.recording is not None
    assert problem.recording.warnings == twin.recording.warnings
    # Stops are reported on the log clock, where the recording's start and end are.
    assert problem.stops[0].t_start == pytest.approx(WALL_T0, abs=1e-6)
    summary = summarize_recording(sim, keep_points=False)
    assert summary.trajectory_clock_offset_ns == WALL_T0_NS - sim_start_s * NS
    assert [lidar.clock_shift_ns for lidar in summary.lidars] == [0, 0]


@pytest.mark.parametrize(
    "offsets",
    [
        {topic: -MONTHS_NS for topic in LIDAR_TOPICS},
        {"/lidar_front/points": -MONTHS_NS, "/lidar_rear/points": 3 * NS},
    ],
    ids=["both-months-behind", "behind-and-ahead"],
)
def test_lidar_clock_off_the_trajectorys_is_realigned_like_its_twin(
    tmp_path: Path, offsets: dict[str, int]
) -> None:
    """A real bag: the odometry on the log time, the LiDARs' drivers on clocks of their own."""
    off = _clock_twin(tmp_path, "off", offsets)
    wall = _clock_twin(tmp_path, "wall")

    problem = read_recording(off)
    twin = read_recording(wall)

    assert_same_problem(problem, twin)
    assert problem.recording is not None and twin.recording is not None
    notes = [w for w in problem.recording.warnings if w not in twin.recording.warnings]
    assert len(notes) == 2
    assert notes[0].startswith(
        "clocks disagree: /lidar_front/points's header stamps are 10368000.000 s behind their "
        "log times, the trajectory's (odometry:/odom) 0.000 s behind their log times"
    )
    assert f"shifted by {-offsets['/lidar_rear/points'] / NS:+.3f} s onto" in notes[1]
    summary = summarize_recording(off, keep_points=False)
    assert [lidar.clock_shift_ns for lidar in summary.lidars] == [-offsets[t] for t in LIDAR_TOPICS]


def test_lidar_latency_within_the_tolerance_keeps_its_header_stamps(tmp_path: Path) -> None:
    path = _clock_twin(tmp_path, "late", {"/lidar_rear/points": -40_000_000})

    summary = summarize_recording(path, keep_points=False)

    rear = summary.lidars[1]
    assert (rear.clock_offset_ns, rear.clock_shift_ns) == (40_000_000, 0)
    assert not any("clocks disagree" in note for note in summary.notes)
    tight = ReaderConfig(clock_tolerance_s=0.01)
    assert (
        summarize_recording(path, tight, keep_points=False).lidars[1].clock_shift_ns == 40_000_000
    )
