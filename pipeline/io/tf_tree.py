"""The static transform tree from `/tf_static`: chains such as `base_link -> mount -> lidar`."""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.io.errors import CorruptRecordingError
from pipeline.transforms import Matrix4, from_translation_xyzw, invert


def normalize_frame(name: str) -> str:
    """Frame ids without the leading `/` that ROS 1 tf allowed (`/base_link` is `base_link`)."""
    return name.lstrip("/")


class BadTransformError(ValueError):
    """A `geometry_msgs/Transform` that is no transform (a damaged recording)."""


def transform_matrix(transform: Any) -> Matrix4:
    """`T_parent_child` (4, 4) from a `geometry_msgs/Transform`; `BadTransformError` when it is
    none (a NaN or infinite translation, a quaternion without direction)."""
    t, q = transform.translation, transform.rotation
    translation = np.array([t.x, t.y, t.z], dtype=np.float64)
    try:
        if not np.isfinite(translation).all():
            raise ValueError(f"translation {translation.tolist()} is not finite")
        return from_translation_xyzw(translation, (q.x, q.y, q.z, q.w))
    except ValueError as err:
        raise BadTransformError(str(err)) from err


def message_edges(msg: Any) -> list[tuple[str, str, Matrix4]]:
    """`(parent, child, T_parent_child)` of every transform of a `tf2_msgs/TFMessage`, frames
    normalised; `BadTransformError` naming the first edge that holds no transform."""
    edges = []
    for stamped in msg.transforms:
        parent = normalize_frame(stamped.header.frame_id)
        child = normalize_frame(stamped.child_frame_id)
        try:
            edges.append((parent, child, transform_matrix(stamped.transform)))
        except BadTransformError as err:
            raise BadTransformError(f"the edge {parent} -> {child}: {err}") from err
    return edges


def damaged_tf_static(path: object, err: BadTransformError) -> CorruptRecordingError:
    """The error to raise when `/tf_static` of the recording at `path` holds `err`."""
    return CorruptRecordingError(
        f"{path}: /tf_static is damaged ({err}); copy the recording again, or give the LiDARs' "
        "extrinsics in the config"
    )


class TransformTree:
    """A forest of `parent -> child` edges; each child has one parent (a later edge replaces it)."""

    def __init__(self) -> None:
        self._parent: dict[str, tuple[str, Matrix4]] = {}

    def add(self, parent: str, child: str, T_parent_child: Matrix4) -> None:
        self._parent[normalize_frame(child)] = (normalize_frame(parent), T_parent_child)

    def add_message(self, msg: Any) -> None:
        """Every edge of a `tf2_msgs/TFMessage` (see `message_edges`)."""
        for parent, child, T_parent_child in message_edges(msg):
            self.add(parent, child, T_parent_child)

    @property
    def frames(self) -> frozenset[str]:
        return frozenset(self._parent) | {parent for parent, _ in self._parent.values()}

    def __len__(self) -> int:
        return len(self._parent)

    def lookup(self, parent: str, child: str) -> Matrix4 | None:
        """`T_parent_child` via the tree (up from both frames to a shared ancestor), else None."""
        parent, child = normalize_frame(parent), normalize_frame(child)
        up_parent = self._path_to_root(parent)
        up_child = self._path_to_root(child)
        shared = next((frame for frame in up_child if frame in up_parent), None)
        if shared is None:
            return None
        return invert(up_parent[shared]) @ up_child[shared]

    def _path_to_root(self, frame: str) -> dict[str, Matrix4]:
        """`T_ancestor_frame` for the frame itself and every ancestor, nearest first."""
        chain: dict[str, Matrix4] = {frame: np.eye(4)}
        T = np.eye(4)
        while frame in self._parent:
            parent, T_parent_frame = self._parent[frame]
            if parent in chain:  # a cycle in a damaged recording: stop rather than loop forever
                break
            T = T_parent_frame @ T
            chain[parent] = T
            frame = parent
        return chain
