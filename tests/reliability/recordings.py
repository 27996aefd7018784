"""Bad recordings, each as the bytes a robot would upload: every one passes the upload's magic-byte
check (it is an MCAP file, a ROS 1 bag or an archive) and is wrong inside, in one way.

Built with `pipeline.io.writer.RecordingWriter`, through the reader tests' stop-and-go scene
(`tests.pipeline.io.recordings`) where it has the knob, directly where it does not."""

from __future__ import annotations

import io
import stat
import struct
import tarfile
import tempfile
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.io.writer import RecordingWriter, WriterFormat
from pipeline.transforms import from_xyz_rpy
from tests.pipeline.io.recordings import NS, Spec, write_recording

SMALL = Spec(stops=2, points=60, dwell_s=1.5, move_s=0.5, odom_hz=20, scan_hz=5)
BAG_DIR = "calibration_bag"


def _scene(spec: Spec, fmt: WriterFormat = WriterFormat.ROS2_MCAP) -> bytes:
    with tempfile.TemporaryDirectory() as scratch:
        path = Path(scratch) / "bag"
        write_recording(path, fmt, spec)
        return path.read_bytes() if path.is_file() else (path / "bag.mcap").read_bytes()


def _written(write: Callable[[RecordingWriter], None]) -> bytes:
    with tempfile.TemporaryDirectory() as scratch:
        path = Path(scratch) / "bag"
        with RecordingWriter(path, WriterFormat.ROS2_MCAP) as writer:
            write(writer)
        return (path / "bag.mcap").read_bytes()


def _header(writer: RecordingWriter, stamp: int, frame_id: str) -> Any:
    types = writer.types
    time = types["builtin_interfaces/msg/Time"](sec=stamp // NS, nanosec=stamp % NS)
    return types["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)


def _trajectory_and_tf(writer: RecordingWriter, *, nan_odometry: bool = False) -> None:
    """Three seconds of standing still (one long stop) and a tf_static tree for both LiDARs."""
    edges = [
        ("base_link", "lidar_front", from_xyz_rpy([0.3, 0, 0.5], [0, 0, 0])),
        ("base_link", "lidar_rear", from_xyz_rpy([-0.3, 0, 0.5], [0, 0, np.pi])),
    ]
    writer.write_transforms(100 * NS, edges, static=True)
    for t in np.arange(100.0, 103.0, 0.05):
        pose = from_xyz_rpy([0.0, 0, 0], [0, 0, 0])
        if nan_odometry:
            pose[:3, 3] = np.nan
        writer.write_odometry("/odom", round(t * NS), pose)


def images_only() -> bytes:
    """A camera recording: images, odometry and tf, no PointCloud2 at all."""

    def write(writer: RecordingWriter) -> None:
        _trajectory_and_tf(writer)
        types = writer.types
        for t in np.arange(100.0, 103.0, 0.2):
            stamp = round(t * NS)
            header = _header(writer, stamp, "camera")
            image = types["sensor_msgs/msg/Image"](
                header=header,
                height=4,
                width=4,
                encoding="mono8",
                is_bigendian=0,
                step=4,
                data=np.zeros(16, dtype=np.uint8),
            )
            writer.write_raw("/camera/image_raw", "sensor_msgs/msg/Image", stamp, image)

    return _written(write)


def non_finite_clouds(value: float) -> bytes:
    """Both LiDARs publish scans whose every point is `value` (NaN or an infinity)."""

    def write(writer: RecordingWriter) -> None:
        _trajectory_and_tf(writer)
        for t in np.arange(100.0, 103.0, 0.2):
            for lidar in ("lidar_front", "lidar_rear"):
                points = np.full((50, 3), value)
                writer.write_pointcloud(f"/{lidar}/points", round(t * NS), lidar, points)

    return _written(write)


def nan_odometry() -> bytes:
    """Good clouds, but every odometry position is NaN."""

    def write(writer: RecordingWriter) -> None:
        _trajectory_and_tf(writer, nan_odometry=True)
        rng = np.random.default_rng(0)
        for t in np.arange(100.0, 103.0, 0.2):
            for lidar in ("lidar_front", "lidar_rear"):
                points = rng.uniform(-5, 5, (50, 3))
                writer.write_pointcloud(f"/{lidar}/points", round(t * NS), lidar, points)

    return _written(write)


def integer_coordinates() -> bytes:
    """Clouds whose x, y, z are int32 (a driver's raw counts, not metres)."""

    def write(writer: RecordingWriter) -> None:
        _trajectory_and_tf(writer)
        types = writer.types
        for t in np.arange(100.0, 103.0, 0.2):
            stamp = round(t * NS)
            for lidar in ("lidar_front", "lidar_rear"):
                header = _header(writer, stamp, lidar)
                fields = [
                    types["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=5, count=1)
                    for i, n in enumerate("xyz")
                ]
                cloud = types["sensor_msgs/msg/PointCloud2"](
                    header=header,
                    height=1,
                    width=10,
                    fields=fields,
                    is_bigendian=False,
                    point_step=12,
                    row_step=120,
                    data=np.ones(120, dtype=np.uint8),
                    is_dense=True,
                )
                writer.write_raw(f"/{lidar}/points", "sensor_msgs/msg/PointCloud2", stamp, cloud)

    return _written(write)


def empty_mcap() -> bytes:
    """A well-formed MCAP recording with no message at all."""
    return _written(lambda writer: None)


def one_lidar() -> bytes:
    return _scene(Spec(**{**SMALL.__dict__, "lidars": ("lidar_front",)}))


def no_trajectory() -> bytes:
    """No odometry and no /tf: nothing says how the robot moved."""
    return _scene(Spec(**{**SMALL.__dict__, "trajectory": "none"}))


def no_tf_static() -> bytes:
    """No /tf_static: nothing says where the LiDARs sit on the robot."""
    return _scene(Spec(**{**SMALL.__dict__, "tf_static": False}))


def never_stops() -> bytes:
    """The robot never stands still long enough for a stop."""
    return _scene(Spec(**{**SMALL.__dict__, "dwell_s": 0.2, "move_s": 0.5, "stops": 4}))


def good_mcap() -> bytes:
    return _scene(SMALL)


def truncated(data: bytes) -> bytes:
    return data[: len(data) // 2]


def ros1_truncated() -> bytes:
    return truncated(_scene(SMALL, WriterFormat.ROS1))


# -- archives ------------------------------------------------------------------------------------


def zip_with_member(name: str, data: bytes, *, mode: int | None = None) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr(f"{BAG_DIR}/metadata.yaml", "rosbag2_bagfile_information: {}\n")
        info = zipfile.ZipInfo(name)
        if mode is not None:
            info.external_attr = mode << 16
        archive.writestr(info, data)
    return buffer.getvalue()


def zip_traversal() -> bytes:
    return zip_with_member("../../../../tmp/fleetcal-escaped.mcap", good_mcap())


def zip_symlink() -> bytes:
    return zip_with_member(f"{BAG_DIR}/bag.mcap", b"/etc/passwd", mode=stat.S_IFLNK | 0o777)


def tar_with(member: tarfile.TarInfo, data: bytes = b"", *, gz: bool = False) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz" if gz else "w") as archive:
        archive.addfile(member, io.BytesIO(data) if data else None)
    return buffer.getvalue()


def tar_traversal() -> bytes:
    data = good_mcap()
    member = tarfile.TarInfo("/tmp/fleetcal-escaped/bag.mcap")
    member.size = len(data)
    return tar_with(member, data)


def tar_symlink() -> bytes:
    member = tarfile.TarInfo(f"{BAG_DIR}/bag.mcap")
    member.type, member.linkname = tarfile.SYMTYPE, "/etc/passwd"
    return tar_with(member)


def tar_hardlink() -> bytes:
    member = tarfile.TarInfo(f"{BAG_DIR}/bag.mcap")
    member.type, member.linkname = tarfile.LNKTYPE, "/etc/shadow"
    return tar_with(member)


def zip_bomb(members: int = 4000, kernel_bytes: int = 10 * 2**20) -> bytes:
    """Overlapping members (Fifield's construction, unquoted): one deflated kernel of zeros that
    every central-directory entry points at, so 4000 entries of 10 MiB each (40 GiB) cost one
    kernel's ~10 KB. The declared sizes give it away before anything is written."""
    kernel = zlib.compressobj(9, zlib.DEFLATED, -15)
    compressed = kernel.compress(b"\0" * kernel_bytes) + kernel.flush()
    crc = zlib.crc32(b"\0" * kernel_bytes)
    name = b"bomb"
    local = struct.pack(
        "<IHHHHHIIIHH", 0x04034B50, 20, 0, 8, 0, 0, crc, len(compressed), kernel_bytes, 4, 0
    )
    body = local + name + compressed
    central = b""
    for index in range(members):
        entry = f"{BAG_DIR}/part_{index:05d}".encode()
        central += (
            struct.pack(
                "<IHHHHHHIIIHHHHHII",
                0x02014B50,
                20,
                20,
                0,
                8,
                0,
                0,
                crc,
                len(compressed),
                kernel_bytes,
                len(entry),
                0,
                0,
                0,
                0,
                0,
                0,
            )
            + entry
        )
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, members, members, len(central), len(body), 0)
    return body + central + end


def tar_gz_bomb() -> bytes:
    """A .tar.gz whose one member claims 40 GiB of zeros (the header is all that is sent: the
    reader must refuse it from the header, before it writes a byte)."""
    member = tarfile.TarInfo(f"{BAG_DIR}/bag.mcap")
    member.size = 40 * 2**30
    header = member.tobuf(format=tarfile.GNU_FORMAT)
    stream = zlib.compressobj(9, zlib.DEFLATED, 31)
    return stream.compress(header + b"\0" * 2**20) + stream.flush(zlib.Z_SYNC_FLUSH)
