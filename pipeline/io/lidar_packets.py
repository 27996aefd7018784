"""Raw LiDAR packet topics: recognised by message type, so that a recording holding packets but no
PointCloud2 is refused with how to turn its packets into point clouds.

No decoder is built in: fleetcal reads the PointCloud2 every driver publishes. (velodyne-decoder
decodes VelodyneScan and ouster-sdk Ouster packets, but each covers one vendor and needs the
sensor's calibration or metadata from the recording; the driver's own node does it right.)
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class PacketDriver:
    """A driver's packet message types and how to get PointCloud2 from a recording of them."""

    vendor: str
    msgtypes: tuple[str, ...]
    convert: str


DRIVERS = (
    PacketDriver(
        "Velodyne",
        ("velodyne_msgs/msg/VelodyneScan", "velodyne_msgs/msg/VelodynePacket"),
        "play the recording through velodyne_pointcloud's transform node (ROS 1: "
        "`roslaunch velodyne_pointcloud <model>_points.launch`, ROS 2: "
        "`ros2 launch velodyne_pointcloud velodyne_transform_node-<model>-launch.py`)",
    ),
    PacketDriver(
        "Ouster",
        (
            "ouster_sensor_msgs/msg/PacketMsg",
            "ouster_msgs/msg/PacketMsg",
            "ouster_ros/msg/PacketMsg",
            "ouster_sensor_msgs/msg/LidarPacket",
        ),
        "play the recording through ouster-ros in replay mode (`ros2 launch ouster_ros "
        "replay.launch.xml bag_file:=...`, which needs the recorded /ouster/metadata)",
    ),
    PacketDriver(
        "Livox",
        ("livox_ros_driver2/msg/CustomMsg", "livox_ros_driver/msg/CustomMsg"),
        "record with livox_ros_driver2's `xfer_format: 0` (PointCloud2), or convert each "
        "CustomMsg to PointCloud2 with a converter node while playing the recording",
    ),
    PacketDriver(
        "Hesai",
        (
            "pandar_msgs/msg/PandarScan",
            "pandar_msgs/msg/PandarPacket",
            "hesai_ros_driver/msg/UdpFrame",
            "hesai_ros_driver/msg/UdpPacket",
        ),
        "play the recording through the Hesai driver with the bag's packets as its source "
        "(HesaiLidar_ROS_2.0 `source_type: 3`, or pandar_pointcloud)",
    ),
    PacketDriver(
        "Robosense",
        (
            "rslidar_msg/msg/RslidarPacket",
            "rslidar_msgs/msg/rslidarScan",
            "rslidar_msgs/msg/rslidarPacket",
        ),
        "play the recording through rslidar_sdk with `msg_source: 2` (packets from ROS)",
    ),
    PacketDriver(
        "Autoware nebula",
        ("nebula_msgs/msg/NebulaPackets", "nebula_msgs/msg/NebulaPacket"),
        "play the recording through nebula's ROS wrapper with its decoder enabled",
    ),
)
_BY_TYPE = {msgtype: driver for driver in DRIVERS for msgtype in driver.msgtypes}


def packet_topics(connections: Iterable[tuple[str, str]]) -> dict[str, tuple[str, PacketDriver]]:
    """Of `(topic, msgtype)` pairs, the packet topics: topic -> (msgtype, its driver)."""
    return {
        topic: (msgtype, _BY_TYPE[msgtype])
        for topic, msgtype in sorted(set(connections))
        if msgtype in _BY_TYPE
    }


def packets_message(path: str, topics: dict[str, tuple[str, PacketDriver]]) -> str:
    """What to tell the user whose recording holds LiDAR packets and no PointCloud2."""
    found = ", ".join(f"{topic} ({msgtype})" for topic, (msgtype, _) in topics.items())
    drivers = {driver.vendor: driver.convert for _, driver in topics.values()}
    how = "; ".join(f"{vendor}: {convert}" for vendor, convert in drivers.items())
    return (
        f"{path} has no sensor_msgs/PointCloud2 topic, only raw LiDAR packets: {found}. "
        f"fleetcal reads point clouds, not packets. Convert them: {how}; record the PointCloud2 "
        "topics it publishes together with /odom (or /tf) and /tf_static (`ros2 bag record` or "
        "`rosbag record`), and upload that recording"
    )
