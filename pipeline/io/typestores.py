"""The rosbags type stores we read and write with, with the types the stock stores lack."""

from __future__ import annotations

from functools import cache

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
ODOMETRY = "nav_msgs/msg/Odometry"


@cache
def ros2_typestore() -> Typestore:
    """ROS 2 Humble types: PointCloud2, Odometry and TFMessage are all built in."""
    return get_typestore(Stores.ROS2_HUMBLE)


@cache
def ros1_typestore() -> Typestore:
    """ROS 1 Noetic types plus `tf2_msgs/msg/TFMessage`, which the stock ROS 1 store lacks."""
    store = get_typestore(Stores.ROS1_NOETIC)
    if TF_MESSAGE not in store.types:
        store.register(
            get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_MESSAGE)
        )
    return store
