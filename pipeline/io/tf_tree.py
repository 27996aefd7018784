"""The static transform tree from `/tf_static`: chains such as `base_link -> mount -> lidar`."""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.transforms import Matrix4, from_translation_xyzw, invert


def normalize_frame(name: str) -> str:
    """Frame ids without the leading `/` that ROS 1 tf allowed (`/base_link` is `base_link`)."""
    return name.lstrip("/")


def transform_matrix(transform: Any) -> Matrix4:
    """`T_parent_child` (4, 4) from a `geometry_msgs/Transform`."""
    t, q = transform.translation, transform.rotation
    return from_translation_xyzw((t.x, t.y, t.z), (q.x, q.y, q.z, q.w))


class TransformTree:
    """A forest of `parent -> child` edges; each child has one parent (a later edge replaces it)."""

    def __init__(self) -> None:
        self._parent: dict[str, tuple[str, Matrix4]] = {}

    def add(self, parent: str, child: str, T_parent_child: Matrix4) -> None:
        self._parent[normalize_frame(child)] = (normalize_frame(parent), T_parent_child)

    def add_message(self, msg: Any) -> None:
        """Every edge of a `tf2_msgs/TFMessage`."""
        for stamped in msg.transforms:
            self.add(
                stamped.header.frame_id, stamped.child_frame_id, transform_matrix(stamped.transform)
            )

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
