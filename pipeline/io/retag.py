"""A calibrated copy of a recording: every message copied byte for byte except `/tf_static`, which
is replaced by one latched message whose LiDAR edges give the calibrated `T_base_lidar`.

The static tree keeps its shape: a LiDAR that hangs from a mount frame still does, with
`T_mount_lidar = T_mount_base @ T_base_lidar`, so Foxglove and RViz show the robot as built. ROS 2
inputs (any storage, bare files, archives) become an MCAP bag directory; ROS 1 stays ROS 1.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags import rosbag1, rosbag2
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag1,
    ConnectionExtRosbag2,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from pipeline.io.config import ArchiveLimits
from pipeline.io.errors import RecordingError
from pipeline.io.motion import TF_TYPES
from pipeline.io.source import OpenRecording, open_recording, reading_errors
from pipeline.io.tf_tree import (
    BadTransformError,
    TransformTree,
    damaged_tf_static,
    message_edges,
    normalize_frame,
)
from pipeline.io.typestores import TF_MESSAGE, ros1_typestore, ros2_typestore
from pipeline.transforms import Matrix4, to_translation_xyzw

TF_STATIC = "/tf_static"

# What `static_transform_publisher` offers: latched (transient local), reliable, depth 1.
_UNSPECIFIED = QosTime(sec=0, nsec=0)
TF_STATIC_QOS = Qos(
    history=QosHistory.KEEP_LAST,
    depth=1,
    reliability=QosReliability.RELIABLE,
    durability=QosDurability.TRANSIENT_LOCAL,
    deadline=_UNSPECIFIED,
    lifespan=_UNSPECIFIED,
    liveliness=QosLiveliness.AUTOMATIC,
    liveliness_lease_duration=_UNSPECIFIED,
    avoid_ros_namespace_conventions=False,
)


@dataclass(frozen=True)
class StaticEdge:
    """One `/tf_static` edge, `T_parent_child` (4, 4)."""

    parent: str
    child: str
    T_parent_child: Matrix4


@dataclass(frozen=True)
class RetagResult:
    """What was written. `path` is the file a viewer opens (the `.mcap` inside the bag directory
    `directory`, or the ROS 1 `.bag`); `edges` the new `/tf_static`; `skipped` topics whose
    message definitions the source did not carry (they cannot be written without one)."""

    path: Path
    directory: Path | None
    format: str
    messages: int
    replaced_messages: int
    edges: tuple[StaticEdge, ...]
    skipped: tuple[str, ...] = ()


def write_calibrated_recording(
    source: Path | str,
    destination: Path | str,
    T_base_lidar: Mapping[str, Matrix4],
    *,
    base_frame: str = "base_link",
    limits: ArchiveLimits | None = None,
    scratch_dir: Path | None = None,
) -> RetagResult:
    """Copy the recording at `source` to `destination` (which must not exist) with `/tf_static`
    holding `T_base_lidar[frame]` (4, 4) for each LiDAR frame and every other static edge as it
    was. ROS 2 sources give a bag directory at `destination`, ROS 1 sources a `.bag` file.
    """
    destination = Path(destination)
    if destination.exists():
        raise RecordingError(f"{destination} already exists; choose a new output path")
    if not T_base_lidar:
        raise RecordingError("no calibrated extrinsics given; there is nothing to write")
    base = normalize_frame(base_frame)
    calibrated = {normalize_frame(frame): np.asarray(T) for frame, T in T_base_lidar.items()}
    with open_recording(Path(source), limits=limits, scratch_dir=scratch_dir) as opened:
        static = [c for c in opened.connections if c.topic == TF_STATIC and c.msgtype in TF_TYPES]
        original = _read_static_edges(opened, static)
        edges = calibrated_static_edges(original, calibrated, base)
        copied = [c for c in opened.connections if c.topic != TF_STATIC]
        ros1 = opened.storage.holds_ros1_messages
        destination.parent.mkdir(parents=True, exist_ok=True)
        write = _copy_ros1 if ros1 else _copy_ros2
        messages, skipped = write(_Plan(opened, copied, static, edges), destination)
    if ros1:
        return RetagResult(
            destination, None, "ros1", messages, sum(c.msgcount for c in static), edges, skipped
        )
    return RetagResult(
        destination / f"{destination.name}.mcap",
        destination,
        "ros2-mcap",
        messages,
        sum(c.msgcount for c in static),
        edges,
        skipped,
    )


def calibrated_static_edges(
    original: list[StaticEdge], T_base_lidar: Mapping[str, Matrix4], base: str
) -> tuple[StaticEdge, ...]:
    """The new static tree: each LiDAR's edge re-expressed under its old parent so the chain from
    `base` composes to the calibrated `T_base_lidar`; LiDARs missing from the tree (extrinsics
    from the config) hang from `base`. Other edges are kept, a later edge replacing an earlier
    one for the same child as tf does."""
    by_child: dict[str, StaticEdge] = {}
    for edge in original:
        by_child[edge.child] = edge
    tree = TransformTree()
    for edge in by_child.values():
        tree.add(edge.parent, edge.child, edge.T_parent_child)

    def depth(frame: str) -> int:
        seen: set[str] = set()
        while frame in by_child and frame not in seen:
            seen.add(frame)
            frame = by_child[frame].parent
        return len(seen)

    # Ancestors first, so a LiDAR mounted on another LiDAR sees its parent already calibrated.
    for frame in sorted(T_base_lidar, key=lambda f: (depth(f), f)):
        T_base = np.asarray(T_base_lidar[frame], dtype=np.float64)
        parent = by_child[frame].parent if frame in by_child else base
        T_parent_base = None if parent == base else tree.lookup(parent, base)
        if T_parent_base is None or _below(frame, parent, by_child):
            parent, T_parent_base = base, np.eye(4)
        edge = StaticEdge(parent, frame, T_parent_base @ T_base)
        by_child[frame] = edge
        tree.add(edge.parent, edge.child, edge.T_parent_child)
    return tuple(by_child.values())


def _below(frame: str, parent: str, by_child: Mapping[str, StaticEdge]) -> bool:
    """Whether `parent` hangs (directly or not) from `frame`: keeping it would make a cycle."""
    seen: set[str] = set()
    while parent in by_child and parent not in seen:
        if parent == frame:
            return True
        seen.add(parent)
        parent = by_child[parent].parent
    return parent == frame


def _read_static_edges(opened: OpenRecording, connections: list[Connection]) -> list[StaticEdge]:
    edges: list[StaticEdge] = []
    with reading_errors(opened.path, opened.storage):
        for connection, _, raw in opened.messages(connections):
            msg: Any = opened.deserialize(raw, connection)
            try:
                edges += [StaticEdge(*edge) for edge in message_edges(msg)]
            except BadTransformError as err:
                raise damaged_tf_static(opened.path, err) from err
    return edges


# -- writers ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Plan:
    """The open source, the connections copied as they are, the `/tf_static` ones it replaces,
    and the new static edges."""

    opened: OpenRecording
    copied: list[Connection]
    static: list[Connection]
    edges: tuple[StaticEdge, ...]


def _copy_ros2(plan: _Plan, destination: Path) -> tuple[int, tuple[str, ...]]:
    opened, copied, static, edges = plan.opened, plan.copied, plan.static, plan.edges
    store = ros2_typestore()
    writer = rosbag2.Writer(destination, version=9, storage_plugin=rosbag2.StoragePlugin.MCAP)
    targets: dict[int, Connection] = {}
    skipped: list[str] = []
    count = 0
    with writer:
        # The source's QoS for /tf_static when it recorded one, else the publisher's own.
        qos = [
            q
            for c in static
            if isinstance(c.ext, ConnectionExtRosbag2)
            for q in c.ext.offered_qos_profiles
        ][:1] or [TF_STATIC_QOS]
        tf = writer.add_connection(TF_STATIC, TF_MESSAGE, typestore=store, offered_qos_profiles=qos)
        message = _tf_message(store, edges, opened.start_time, ros1=False)
        writer.write(tf, opened.start_time, store.serialize_cdr(message, TF_MESSAGE))
        count += 1
        added: dict[tuple[str, str], Connection] = {}
        for connection in copied:
            ext = connection.ext
            assert isinstance(ext, ConnectionExtRosbag2)
            key = (connection.topic, connection.msgtype)
            if key in added:
                targets[id(connection)] = added[key]
                continue
            if connection.msgtype in store.types:
                kwargs: dict[str, Any] = {"typestore": store}
            elif connection.msgdef.data and connection.digest.startswith("RIHS01_"):
                kwargs = {"msgdef": connection.msgdef.data, "rihs01": connection.digest}
            else:
                skipped.append(connection.topic)
                continue
            added[key] = targets[id(connection)] = writer.add_connection(
                connection.topic,
                connection.msgtype,
                serialization_format=ext.serialization_format,
                offered_qos_profiles=ext.offered_qos_profiles,
                **kwargs,
            )
        count += _copy_messages(opened, copied, targets, writer.write)
    return count, tuple(skipped)


def _copy_ros1(plan: _Plan, destination: Path) -> tuple[int, tuple[str, ...]]:
    opened, copied, edges = plan.opened, plan.copied, plan.edges
    store = ros1_typestore()
    writer = rosbag1.Writer(destination)
    targets: dict[int, Connection] = {}
    with writer:
        tf = writer.add_connection(TF_STATIC, TF_MESSAGE, typestore=store, latching=1)
        message = _tf_message(store, edges, opened.start_time, ros1=True)
        writer.write(tf, opened.start_time, store.serialize_ros1(message, TF_MESSAGE))
        added: dict[tuple[Any, ...], Connection] = {}
        for connection in copied:
            ext = connection.ext
            assert isinstance(ext, ConnectionExtRosbag1)
            key = (connection.topic, connection.msgtype, connection.digest, ext.callerid)
            if key not in added:
                added[key] = writer.add_connection(
                    connection.topic,
                    connection.msgtype,
                    msgdef=connection.msgdef.data,
                    md5sum=connection.digest,
                    callerid=ext.callerid,
                    latching=ext.latching,
                )
            targets[id(connection)] = added[key]
        count = 1 + _copy_messages(opened, copied, targets, writer.write)
    return count, ()


def _copy_messages(
    opened: OpenRecording,
    connections: list[Connection],
    targets: Mapping[int, Connection],
    write: Callable[[Connection, int, bytes], None],
) -> int:
    count = 0
    wanted = [c for c in connections if id(c) in targets]
    with reading_errors(opened.path, opened.storage):
        for connection, log_ns, raw in opened.messages(wanted):
            write(targets[id(connection)], log_ns, raw)
            count += 1
    return count


def _tf_message(store: Any, edges: tuple[StaticEdge, ...], stamp_ns: int, *, ros1: bool) -> Any:
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](
        sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)
    )
    transforms = []
    for seq, edge in enumerate(edges):
        translation, quat = to_translation_xyzw(edge.T_parent_child)
        header = (
            types["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=edge.parent)
            if ros1
            else types["std_msgs/msg/Header"](stamp=stamp, frame_id=edge.parent)
        )
        transforms.append(
            types["geometry_msgs/msg/TransformStamped"](
                header=header,
                child_frame_id=edge.child,
                transform=types["geometry_msgs/msg/Transform"](
                    translation=types["geometry_msgs/msg/Vector3"](*translation.tolist()),
                    rotation=types["geometry_msgs/msg/Quaternion"](*quat.tolist()),
                ),
            )
        )
    return types[TF_MESSAGE](transforms=transforms)
