"""Write recordings that follow the input contract: PointCloud2 scans, odometry, /tf, /tf_static.

Used by the synthesiser and by tests; the only writer of bags in the code base (only `pipeline.io`
touches rosbags). Formats: ROS 2 bag directory with MCAP or sqlite3 storage, and ROS 1 `.bag`.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from rosbags import rosbag1, rosbag2

from pipeline.io.errors import RecordingError
from pipeline.io.typestores import (
    ODOMETRY,
    POINTCLOUD2,
    TF_MESSAGE,
    ros1_typestore,
    ros2_typestore,
)
from pipeline.transforms import Matrix4, to_translation_xyzw

# sensor_msgs/PointField datatype codes by numpy kind.
_DATATYPES = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


class WriterFormat(enum.StrEnum):
    ROS2_MCAP = "ros2-mcap"
    ROS2_SQLITE3 = "ros2-sqlite3"
    ROS1 = "ros1"


class RecordingWriter:
    """Context manager writing one recording at `path` (which must not exist yet).

    Timestamps are integer nanoseconds. Every `stamp_ns` argument is the message's log time (the
    bag's receive time); its header stamp is that plus `header_clock_offset_ns`: one offset for
    every topic, or a mapping from topic to offset (topics not in it: 0). 0, the default, writes
    header stamps equal to the log times. A negative offset writes a recording whose publishers
    run on another clock than the recorder: simulated time (Gazebo, Isaac: header stamps from
    0 s while `ros2 bag record` logs the wall clock), or one LiDAR's clock months behind.
    `write_raw` messages keep the header their caller built.
    """

    def __init__(
        self,
        path: Path,
        fmt: WriterFormat = WriterFormat.ROS2_MCAP,
        *,
        header_clock_offset_ns: int | Mapping[str, int] = 0,
    ) -> None:
        self.path = Path(path)
        self.format = WriterFormat(fmt)
        if self.path.exists():
            raise RecordingError(f"{self.path} already exists; choose a new output path")
        self._header_offsets: Mapping[str, int] = (
            {} if isinstance(header_clock_offset_ns, int) else dict(header_clock_offset_ns)
        )
        self._header_offset = (
            header_clock_offset_ns if isinstance(header_clock_offset_ns, int) else 0
        )
        self._ros1 = self.format is WriterFormat.ROS1
        self._store = ros1_typestore() if self._ros1 else ros2_typestore()
        self._writer: rosbag1.Writer | rosbag2.Writer
        if self._ros1:
            self._writer = rosbag1.Writer(self.path)
        else:
            plugin = (
                rosbag2.StoragePlugin.MCAP
                if self.format is WriterFormat.ROS2_MCAP
                else rosbag2.StoragePlugin.SQLITE3
            )
            self._writer = rosbag2.Writer(self.path, version=9, storage_plugin=plugin)
        self._connections: dict[str, Any] = {}
        self._seq = 0

    def __enter__(self) -> RecordingWriter:
        self._writer.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._writer.close()

    # -- messages ---------------------------------------------------------------------------

    def write_pointcloud(
        self,
        topic: str,
        stamp_ns: int,
        frame_id: str,
        points: NDArray[np.floating[Any]],
        *,
        extra_fields: Mapping[str, NDArray[Any]] | None = None,
        dtype: type[np.floating[Any]] = np.float32,
        big_endian: bool = False,
    ) -> None:
        """One scan: (N, 3) `points` in `frame_id` as `dtype`, plus optional per-point scalar
        fields, each stored in its own array's type (e.g. a spinning LiDAR's `ring` as uint16)."""
        points = np.asarray(points)
        order: Literal[">", "<"] = ">" if big_endian else "<"
        xyz_dtype = np.dtype(dtype)
        fields = {
            "x": points[:, 0].astype(xyz_dtype, copy=False),
            "y": points[:, 1].astype(xyz_dtype, copy=False),
            "z": points[:, 2].astype(xyz_dtype, copy=False),
            **{name: np.asarray(values) for name, values in (extra_fields or {}).items()},
        }
        record = np.empty(
            len(points),
            dtype=[(name, values.dtype.newbyteorder(order)) for name, values in fields.items()],
        )
        for name, values in fields.items():
            record[name] = values
        offsets = {name: int(spec[1]) for name, spec in (record.dtype.fields or {}).items()}
        point_field = self._store.types["sensor_msgs/msg/PointField"]
        msg = self._store.types[POINTCLOUD2](
            header=self._header(topic, stamp_ns, frame_id),
            height=1,
            width=len(points),
            fields=[
                point_field(
                    name=name,
                    offset=offsets[name],
                    datatype=_DATATYPES[record.dtype[name].str[1:]],
                    count=1,
                )
                for name in fields
            ],
            is_bigendian=big_endian,
            point_step=record.dtype.itemsize,
            row_step=record.dtype.itemsize * len(points),
            data=record.view(np.uint8).reshape(-1),
            is_dense=bool(np.isfinite(points).all()),
        )
        self._write(topic, POINTCLOUD2, stamp_ns, msg)

    def write_odometry(
        self,
        topic: str,
        stamp_ns: int,
        T_odom_base: Matrix4,
        *,
        odom_frame: str = "odom",
        base_frame: str = "base_link",
        linear_velocity: Sequence[float] = (0.0, 0.0, 0.0),
        angular_velocity: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        """One `nav_msgs/Odometry`: pose of `base_frame` in `odom_frame`, twist in `base_frame`."""
        types = self._store.types
        translation, quat = to_translation_xyzw(T_odom_base)
        pose = types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](*translation.tolist()),
            orientation=types["geometry_msgs/msg/Quaternion"](*quat.tolist()),
        )
        twist = types["geometry_msgs/msg/Twist"](
            linear=types["geometry_msgs/msg/Vector3"](*map(float, linear_velocity)),
            angular=types["geometry_msgs/msg/Vector3"](*map(float, angular_velocity)),
        )
        msg = types[ODOMETRY](
            header=self._header(topic, stamp_ns, odom_frame),
            child_frame_id=base_frame,
            pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=types["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
        )
        self._write(topic, ODOMETRY, stamp_ns, msg)

    def write_transforms(
        self,
        stamp_ns: int,
        edges: Sequence[tuple[str, str, Matrix4]],
        *,
        static: bool = False,
    ) -> None:
        """One `tf2_msgs/TFMessage` on `/tf` (or `/tf_static`).

        `edges` are `(parent, child, T_parent_child)`.
        """
        types = self._store.types
        topic = "/tf_static" if static else "/tf"
        stamped = []
        for parent, child, T in edges:
            translation, quat = to_translation_xyzw(T)
            stamped.append(
                types["geometry_msgs/msg/TransformStamped"](
                    header=self._header(topic, stamp_ns, parent),
                    child_frame_id=child,
                    transform=types["geometry_msgs/msg/Transform"](
                        translation=types["geometry_msgs/msg/Vector3"](*translation.tolist()),
                        rotation=types["geometry_msgs/msg/Quaternion"](*quat.tolist()),
                    ),
                )
            )
        msg = types[TF_MESSAGE](transforms=stamped)
        self._write(topic, TF_MESSAGE, stamp_ns, msg)

    def write_raw(self, topic: str, msgtype: str, stamp_ns: int, msg: Any) -> None:
        """Any message of a type the type store knows (for tests of unrelated topics)."""
        self._write(topic, msgtype, stamp_ns, msg)

    @property
    def types(self) -> Any:
        """The message classes of this writer's type store, by name."""
        return self._store.types

    # -- internals --------------------------------------------------------------------------

    def _header(self, topic: str, log_ns: int, frame_id: str) -> Any:
        """A `std_msgs/Header` stamped on the topic's header clock (`log_ns` plus its offset)."""
        types = self._store.types
        stamp_ns = int(log_ns) + self._header_offsets.get(topic, self._header_offset)
        if stamp_ns < 0:
            raise RecordingError(
                f"header_clock_offset_ns puts {topic}'s header stamp before 0 ({stamp_ns} ns at "
                f"log time {log_ns} ns); choose an offset no more negative than -(first log time)"
            )
        stamp = types["builtin_interfaces/msg/Time"](
            sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)
        )
        if self._ros1:
            self._seq += 1
            return types["std_msgs/msg/Header"](seq=self._seq, stamp=stamp, frame_id=frame_id)
        return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def _write(self, topic: str, msgtype: str, stamp_ns: int, msg: Any) -> None:
        connection = self._connections.get(topic)
        if connection is None:
            kwargs: dict[str, Any] = {"typestore": self._store}
            if self._ros1 and topic == "/tf_static":
                kwargs["latching"] = 1
            connection = self._writer.add_connection(topic, msgtype, **kwargs)
            self._connections[topic] = connection
        data = (
            self._store.serialize_ros1(msg, msgtype)
            if self._ros1
            else self._store.serialize_cdr(msg, msgtype)
        )
        self._writer.write(connection, int(stamp_ns), data)
