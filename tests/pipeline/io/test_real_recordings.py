"""Recordings as real drivers and tools write them: beam-index fields by other names or none,
MCAP of the ros1 profile, organised clouds with zeros for no return, radar topics, raw packets,
empty files. Each case is a small recording written to `tmp_path` and read back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer as McapWriter
from rosbags import rosbag1
from rosbags.typesys.msg import denormalize_msgtype

from pipeline.io import ReaderConfig, read_recording, summarize_recording
from pipeline.io.errors import (
    EmptyRecordingError,
    LidarPacketsError,
    LidarTopicsError,
    TooFewLidarsError,
    UnknownFormatError,
)
from pipeline.io.inspection import inspect_recording
from pipeline.io.retag import write_calibrated_recording
from pipeline.io.writer import RecordingWriter, WriterFormat
from pipeline.problem import ScanPattern
from pipeline.synth.lidar_models import Mid70, SpinningLidar
from tests.pipeline.io.recordings import TRUE_EXTRINSICS, Spec, write_recording

SMALL = Spec(stops=2, points=50)
# A 16-beam spinning LiDAR at the rear and a Mid-70 rosette at the front, at a tenth of the rate.
MODELS = Spec(
    stops=2,
    models={"lidar_front": Mid70(), "lidar_rear": SpinningLidar()},
    big_endian_lidars=(),
)


def _write(tmp_path: Path, spec: Spec, fmt: WriterFormat = WriterFormat.ROS2_MCAP) -> Path:
    path = tmp_path / "bag"
    write_recording(path, fmt, spec)
    return path


@pytest.mark.parametrize("field", ["ring", "channel", "laser_id"])
def test_each_beam_field_name_marks_a_spinning_lidar(tmp_path: Path, field: str) -> None:
    spec = Spec(**{**MODELS.__dict__, "beam_field": field})
    summary = summarize_recording(_write(tmp_path, spec), keep_points=False)
    front, rear = summary.lidars
    assert rear.scan_pattern is ScanPattern.REPETITIVE and field in rear.scan_pattern_basis
    # The rosette publishes no beam field: its points tell.
    assert front.scan_pattern is ScanPattern.NON_REPETITIVE and "judged" in front.scan_pattern_basis


def test_spinning_lidar_without_a_beam_field_is_judged_repetitive(tmp_path: Path) -> None:
    spec = Spec(**{**MODELS.__dict__, "ring_lidars": ()})
    problem = read_recording(_write(tmp_path, spec))
    patterns = {lidar.frame: lidar.scan_pattern for lidar in problem.lidars}
    assert patterns == {
        "lidar_front": ScanPattern.NON_REPETITIVE,
        "lidar_rear": ScanPattern.REPETITIVE,
    }


def test_unknown_pattern_is_said_by_inspect(tmp_path: Path) -> None:
    """50 points a scan are too few to judge by: the pattern stays unknown, and inspect says
    so, with what stage 1 does about it and how to tell it."""
    path = _write(tmp_path, Spec(**{**SMALL.__dict__, "ring_lidars": ()}))
    document = inspect_recording(path)
    assert [lidar["scan_pattern"] for lidar in document["lidars"]] == ["unknown", "unknown"]
    assert "only 0 scans with 100 or more" in document["lidars"][0]["scan_pattern_basis"]
    said = [w for w in document["warnings"] if "scan pattern unknown" in w]
    assert len(said) == 2
    assert "stage 1 leaves its clouds unfiltered" in said[0]
    assert "denoise.scan_patterns: {lidar_front: repetitive}" in said[0]
    assert read_recording(path).lidar("lidar_front").scan_pattern is ScanPattern.UNKNOWN


# -- MCAP with the ros1 profile ---------------------------------------------------------------


def mcap_convert(bag: Path, target: Path) -> Path:
    """What `mcap convert` writes from a ROS 1 bag: profile ros1, `ros1msg` schemas holding the
    bag's full definitions, `ros1` message encoding, callerid and latching in channel metadata."""
    with rosbag1.Reader(bag) as reader, target.open("wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="ros1", library="test-mcap-convert")
        channels = {}
        for connection in reader.connections:
            schema = writer.register_schema(
                denormalize_msgtype(connection.msgtype),
                "ros1msg",
                connection.msgdef.data.encode(),
            )
            ext = connection.ext
            channels[connection.id] = writer.register_channel(
                connection.topic,
                "ros1",
                schema,
                {"callerid": ext.callerid or "", "latching": str(ext.latching or 0)},  # type: ignore[union-attr]
            )
        for connection, stamp, raw in reader.messages():
            writer.add_message(channels[connection.id], stamp, raw, stamp)
        writer.finish()
    return target


def test_mcap_of_the_ros1_profile_reads_like_its_bag(tmp_path: Path) -> None:
    bag = _write(tmp_path, SMALL, WriterFormat.ROS1)
    converted = mcap_convert(bag, tmp_path / "converted.mcap")

    problem, original = read_recording(converted), read_recording(bag)

    assert problem.recording is not None and problem.recording.format == "mcap"
    assert summarize_recording(converted).storage == "mcap-ros1"
    assert problem.frames == original.frames
    assert len(problem.stops) == len(original.stops) == 2
    for stop, twin in zip(problem.stops, original.stops, strict=True):
        np.testing.assert_array_equal(stop.T_odom_base, twin.T_odom_base)
        for frame in problem.frames:
            np.testing.assert_array_equal(stop.clouds[frame], twin.clouds[frame])
    for lidar, lidar_twin in zip(problem.lidars, original.lidars, strict=True):
        np.testing.assert_array_equal(lidar.T_base_lidar, lidar_twin.T_base_lidar)


def test_mcap_of_the_ros1_profile_is_retagged_into_a_ros1_bag(tmp_path: Path) -> None:
    converted = mcap_convert(_write(tmp_path, SMALL, WriterFormat.ROS1), tmp_path / "c.mcap")
    out = write_calibrated_recording(converted, tmp_path / "calibrated.bag", TRUE_EXTRINSICS)
    assert out.format == "ros1"
    problem = read_recording(out.path)
    np.testing.assert_allclose(
        problem.lidar("lidar_rear").T_base_lidar, TRUE_EXTRINSICS["lidar_rear"], atol=1e-9
    )


def test_mcap_of_another_profile_is_refused_with_what_is_read(tmp_path: Path) -> None:
    path = tmp_path / "protobuf.mcap"
    with path.open("wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="protobuf-telemetry")
        writer.finish()
    with pytest.raises(UnknownFormatError, match=r"profile 'protobuf-telemetry'.*ros1"):
        read_recording(path)


# -- clouds as drivers publish them -------------------------------------------------------------


def test_organised_clouds_with_zeros_for_no_return_decode_right(tmp_path: Path) -> None:
    """Ouster-like: 4 rows of 75 points with padded rows, a third of them zeros (no return)
    and no NaN; the zeros are dropped, every other point kept, as for a flat cloud."""
    spec = Spec(
        stops=2,
        points=300,
        nan_fraction=0.0,
        zero_fraction=1 / 3,
        organised_lidars=("lidar_front", "lidar_rear"),
        big_endian_lidars=(),
    )
    path = _write(tmp_path, spec)
    flat = _write(tmp_path / "flat", Spec(**{**spec.__dict__, "organised_lidars": ()}))
    problem, twin = read_recording(path), read_recording(flat)
    for stop, flat_stop in zip(problem.stops, twin.stops, strict=True):
        for frame, cloud in stop.clouds.items():
            assert len(cloud) == stop.scan_counts[frame] * 200
            assert stop.scan_sizes[frame] == (200,) * stop.scan_counts[frame]
            assert not (cloud == 0).all(axis=1).any()
            np.testing.assert_array_equal(cloud, flat_stop.clouds[frame])


# -- topics that are not LiDARs -----------------------------------------------------------------


def test_radar_topics_are_left_out_with_a_warning(tmp_path: Path) -> None:
    path = _write(tmp_path, Spec(**{**SMALL.__dict__, "radar_topics": ("/radar/points",)}))
    document = inspect_recording(path)
    assert [lidar["topic"] for lidar in document["lidars"]] == [
        "/lidar_front/points",
        "/lidar_rear/points",
    ]
    (said,) = [w for w in document["warnings"] if "/radar/points" in w]
    assert "rcs, v_r, snr are a radar's" in said and "reader.lidar_topics" in said


def test_a_radar_named_in_lidar_topics_is_read(tmp_path: Path) -> None:
    path = _write(tmp_path, Spec(**{**SMALL.__dict__, "radar_topics": ("/radar/points",)}))
    topics = ("/lidar_front/points", "/radar/points")
    summary = summarize_recording(path, ReaderConfig(lidar_topics=topics), keep_points=False)
    assert [lidar.topic for lidar in summary.lidars] == list(topics)
    (said,) = [n for n in summary.notes if "left out" in n]
    assert "/lidar_rear/points" in said and "add them to reader.lidar_topics" in said


def test_radar_left_out_leaves_too_few_lidars_and_says_why(tmp_path: Path) -> None:
    spec = Spec(**{**SMALL.__dict__, "lidars": ("lidar_front",), "radar_topics": ("/radar",)})
    with pytest.raises(TooFewLidarsError, match=r"1 LiDAR.*/radar left out: its fields rcs"):
        read_recording(_write(tmp_path, spec))


def test_two_topics_in_one_frame_name_the_path_and_lidar_topics(tmp_path: Path) -> None:
    path = tmp_path / "dup"
    with RecordingWriter(path, WriterFormat.ROS2_MCAP) as writer:
        for k in range(30):
            writer.write_pointcloud("/a/points", k * 10**8, "lidar", np.ones((10, 3)))
            writer.write_pointcloud("/a/filtered", k * 10**8, "lidar", np.ones((10, 3)))
            writer.write_odometry("/odom", k * 10**8, np.eye(4))
    with pytest.raises(
        LidarTopicsError,
        match=rf"{path}: /a/points and /a/filtered both publish scans in frame 'lidar'.*"
        r"reader.lidar_topics \(e.g. \[/a/points",
    ):
        read_recording(path)


def test_raw_packets_without_point_clouds_say_how_to_convert(tmp_path: Path) -> None:
    path = tmp_path / "packets.bag"
    with rosbag1.Writer(path) as writer:
        for topic, msgtype in [
            ("/velodyne_packets", "velodyne_msgs/msg/VelodyneScan"),
            ("/livox/lidar", "livox_ros_driver2/msg/CustomMsg"),
        ]:
            connection = writer.add_connection(
                topic, msgtype, msgdef="uint8[] data", md5sum="f43a8e1b362b75baa741461b46adc7e0"
            )
            writer.write(connection, 10**9, b"\x00\x00\x00\x00")
    with pytest.raises(
        LidarPacketsError,
        match=r"only raw LiDAR packets: /livox/lidar \(livox_ros_driver2/msg/CustomMsg\), "
        r"/velodyne_packets \(velodyne_msgs/msg/VelodyneScan\).*Livox: .*xfer_format.*"
        r"Velodyne: .*velodyne_pointcloud",
    ):
        read_recording(path)


# -- empty files --------------------------------------------------------------------------------


def test_zero_byte_file_says_it_is_empty(tmp_path: Path) -> None:
    path = tmp_path / "upload.mcap"
    path.touch()
    with pytest.raises(EmptyRecordingError, match=r"upload.mcap is empty \(0 bytes\)"):
        read_recording(path)


@pytest.mark.parametrize("fmt", list(WriterFormat))
def test_bag_without_messages_says_it_is_empty(tmp_path: Path, fmt: WriterFormat) -> None:
    path = tmp_path / "bag"
    with RecordingWriter(path, fmt):
        pass
    with pytest.raises(EmptyRecordingError, match=r"is empty: it holds no message"):
        inspect_recording(path)
