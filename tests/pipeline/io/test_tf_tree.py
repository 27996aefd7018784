"""Static transform chains: composed like tf, through shared ancestors, robust to bad input."""

from __future__ import annotations

import numpy as np

from pipeline.io.tf_tree import TransformTree
from pipeline.transforms import Matrix4, from_xyz_rpy, invert

T_BASE_MOUNT = from_xyz_rpy([0.1, 0.2, 0.3], [0.1, -0.2, 0.3])
T_MOUNT_LIDAR = from_xyz_rpy([-0.4, 0.0, 0.2], [0.0, 0.5, 1.0])
T_BASE_OTHER = from_xyz_rpy([1.0, -1.0, 0.0], [0.0, 0.0, 2.0])


def lookup(tree: TransformTree, parent: str, child: str) -> Matrix4:
    T = tree.lookup(parent, child)
    assert T is not None, f"no chain {parent} -> {child}"
    return T


def tree() -> TransformTree:
    tree = TransformTree()
    tree.add("base_link", "mount", T_BASE_MOUNT)
    tree.add("/mount", "/lidar", T_MOUNT_LIDAR)  # ROS 1 style names reach the same frames
    tree.add("base_link", "other", T_BASE_OTHER)
    return tree


def test_chain_is_composed_parent_first() -> None:
    np.testing.assert_allclose(lookup(tree(), "base_link", "lidar"), T_BASE_MOUNT @ T_MOUNT_LIDAR)


def test_reverse_and_sibling_lookups() -> None:
    np.testing.assert_allclose(
        lookup(tree(), "lidar", "base_link"), invert(T_BASE_MOUNT @ T_MOUNT_LIDAR)
    )
    np.testing.assert_allclose(
        lookup(tree(), "other", "lidar"),
        invert(T_BASE_OTHER) @ T_BASE_MOUNT @ T_MOUNT_LIDAR,
        atol=1e-12,
    )
    np.testing.assert_allclose(lookup(tree(), "lidar", "lidar"), np.eye(4))


def test_unconnected_frames_give_none() -> None:
    t = tree()
    t.add("world", "map", np.eye(4))
    assert t.lookup("base_link", "map") is None
    assert t.lookup("base_link", "nowhere") is None
    assert {"base_link", "mount", "lidar", "other", "world", "map"} == t.frames


def test_later_edge_replaces_earlier() -> None:
    t = tree()
    t.add("base_link", "mount", np.eye(4))
    np.testing.assert_allclose(lookup(t, "base_link", "lidar"), T_MOUNT_LIDAR)


def test_cycle_in_a_damaged_recording_terminates() -> None:
    t = TransformTree()
    t.add("a", "b", T_BASE_MOUNT)
    t.add("b", "a", T_BASE_MOUNT)
    assert t.lookup("a", "c") is None
    assert t.lookup("a", "b") is not None
