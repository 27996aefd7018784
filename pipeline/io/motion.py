"""First pass over a recording: `/tf_static` and the base's trajectory (odometry or `/tf`).

The odometry may describe another body frame than `base` (e.g. `base_footprint`); then the static
chain from that frame to `base` is composed on, as tf itself would. The trajectory is on its own
header clock (see `clocks`), whose offset to the bag's log times is measured here.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.io.clocks import HeaderClock
from pipeline.io.errors import NoTrajectoryError
from pipeline.io.source import OpenRecording, reading_errors, stamp_ns
from pipeline.io.tf_tree import (
    BadTransformError,
    TransformTree,
    damaged_tf_static,
    normalize_frame,
)
from pipeline.io.trajectory import Trajectory, valid_samples
from pipeline.io.typestores import ODOMETRY, TF_MESSAGE
from pipeline.transforms import Matrix4

TF_TYPES = frozenset({TF_MESSAGE, "tf/msg/tfMessage"})  # ROS 1 bags recorded with tf, not tf2


@dataclass(frozen=True)
class Motion:
    """The static tree, the trajectory of `base` in `odom_frame` on the header clock `clock`,
    and notes for the user."""

    tree: TransformTree
    trajectory: Trajectory
    odom_frame: str
    clock: HeaderClock
    notes: tuple[str, ...] = ()


@dataclass
class _Samples:
    """Pose samples of one `parent -> child` edge (header stamp, log time, pose), as flat lists
    until the pass ends."""

    stamps: list[int] = field(default_factory=list)
    logs: list[int] = field(default_factory=list)
    poses: list[tuple[float, ...]] = field(default_factory=list)

    def add(self, stamp_ns: int, log_ns: int, position: Any, orientation: Any) -> None:
        self.stamps.append(stamp_ns)
        self.logs.append(log_ns)
        self.poses.append(
            (
                position.x,
                position.y,
                position.z,
                orientation.x,
                orientation.y,
                orientation.z,
                orientation.w,
            )
        )


def read_motion(
    opened: OpenRecording,
    *,
    trajectory: str,
    odometry_topic: str,
    odom_frame: str,
    base_frame: str,
) -> Motion:
    """Read `/tf_static` and the trajectory (`trajectory`: `auto`, `odometry` or `tf`)."""
    static = [c for c in opened.connections if c.topic == "/tf_static" and c.msgtype in TF_TYPES]
    odometry = [
        c for c in opened.connections if c.topic == odometry_topic and c.msgtype == ODOMETRY
    ]
    dynamic = [c for c in opened.connections if c.topic == "/tf" and c.msgtype in TF_TYPES]
    use_odometry = trajectory == "odometry" or (
        trajectory == "auto" and sum(c.msgcount for c in odometry) > 0
    )
    chosen = odometry if use_odometry else dynamic
    if not chosen:
        raise _no_trajectory(opened, trajectory, odometry_topic, odom_frame, base_frame)

    tree = TransformTree()
    edges: dict[tuple[str, str], _Samples] = defaultdict(_Samples)
    with reading_errors(opened.path, opened.storage):
        for connection, log_ns, raw in opened.messages([*static, *chosen]):
            msg: Any = opened.deserialize(raw, connection)
            if connection.topic == "/tf_static":
                try:
                    tree.add_message(msg)
                except BadTransformError as err:
                    raise damaged_tf_static(opened.path, err) from err
            elif use_odometry:
                key = (
                    normalize_frame(msg.header.frame_id),
                    normalize_frame(msg.child_frame_id) or base_frame,
                )
                pose = msg.pose.pose
                edges[key].add(stamp_ns(msg.header), log_ns, pose.position, pose.orientation)
            else:
                for stamped in msg.transforms:
                    if normalize_frame(stamped.header.frame_id) == odom_frame:
                        key = (odom_frame, normalize_frame(stamped.child_frame_id))
                        edges[key].add(
                            stamp_ns(stamped.header),
                            log_ns,
                            stamped.transform.translation,
                            stamped.transform.rotation,
                        )
    source = f"odometry:{odometry_topic}" if use_odometry else "tf"
    return _trajectory(opened, tree, edges, source, odom_frame, base_frame)


def _trajectory(
    opened: OpenRecording,
    tree: TransformTree,
    edges: dict[tuple[str, str], _Samples],
    source: str,
    odom_frame: str,
    base_frame: str,
) -> Motion:
    where = source.split(":", 1)[-1] if source != "tf" else "/tf"
    if not edges:
        raise NoTrajectoryError(
            f"{opened.path}: {where} has no pose of {base_frame!r} in {odom_frame!r}; "
            f"record the robot's motion there, or set odom_frame / odometry_topic in the config"
        )
    found = _edge_to_base(tree, edges, base_frame)
    if found is None:
        children = sorted({child for _, child in edges})
        raise NoTrajectoryError(
            f"{opened.path}: {where} gives poses of {children}, not of {base_frame!r}, and "
            f"/tf_static does not link them to it; set base_frame in the config to the frame "
            f"the odometry moves, or record the /tf_static chain to {base_frame!r}"
        )
    (parent, child), T_child_base = found
    samples = edges[(parent, child)]
    header = np.asarray(samples.stamps, dtype=np.int64)
    log = np.asarray(samples.logs, dtype=np.int64)
    poses = np.asarray(samples.poses, dtype=np.float64).reshape(-1, 7)
    valid = valid_samples(poses[:, :3], poses[:, 3:])
    notes: list[str] = []
    if not valid.all():
        notes.append(
            f"{int((~valid).sum())} trajectory samples on {where} had a NaN or zero "
            "quaternion and were ignored"
        )
    header, log, poses = header[valid], log[valid], poses[valid]
    clock = HeaderClock.of(header, log)
    stamps = clock.stamp(header, log)
    if len(np.unique(stamps)) < 2:
        raise NoTrajectoryError(
            f"{opened.path}: {where} holds {len(stamps)} usable pose(s) of {child!r}; "
            "stops are found from a trajectory, so record the odometry for the whole routine"
        )
    rotation = Rotation.from_quat(poses[:, 3:])
    R_child_base = Rotation.from_matrix(T_child_base[:3, :3])
    translations = poses[:, :3] + rotation.apply(T_child_base[:3, 3])
    quats = (rotation * R_child_base).as_quat()
    name = source if child == base_frame else f"{source} ({child} -> {base_frame} from /tf_static)"
    return Motion(
        tree,
        Trajectory.from_arrays(stamps, translations, quats, name),
        parent,
        clock,
        tuple(notes),
    )


def _edge_to_base(
    tree: TransformTree, edges: dict[tuple[str, str], _Samples], base_frame: str
) -> tuple[tuple[str, str], Matrix4] | None:
    """The edge to the base itself, else one whose child reaches the base through tf_static."""
    for parent, child in sorted(edges, key=lambda edge: (edge[1] != base_frame, edge)):
        T_child_base = np.eye(4) if child == base_frame else tree.lookup(child, base_frame)
        if T_child_base is not None:
            return (parent, child), T_child_base
    return None


def _no_trajectory(
    opened: OpenRecording, trajectory: str, odometry_topic: str, odom_frame: str, base_frame: str
) -> NoTrajectoryError:
    others = sorted({c.topic for c in opened.connections if c.msgtype == ODOMETRY})
    has_tf = any(c.topic == "/tf" and c.msgtype in TF_TYPES for c in opened.connections)
    wanted = {
        "odometry": f"nav_msgs/Odometry on {odometry_topic}",
        "tf": "/tf",
        "auto": f"nav_msgs/Odometry on {odometry_topic} nor /tf",
    }[trajectory]
    hint = (
        f"; it has Odometry on {others}: set odometry_topic in the config"
        if others
        else "; /tf is there: set trajectory to tf or auto"
        if has_tf
        else ""
    )
    return NoTrajectoryError(
        f"{opened.path} has no trajectory: no {wanted} ({odom_frame} -> {base_frame}){hint}. "
        "The robot's motion must be recorded to find its stops"
    )
