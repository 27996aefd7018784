"""Errors of `pipeline.io`: each says what is wrong with the recording and what the user can do."""

from __future__ import annotations

from pipeline.errors import BadInputError


class RecordingError(BadInputError):
    """Base of every error about a recording's content or format."""


class UnknownFormatError(RecordingError):
    """The file is not a recording we can read (checked by its magic bytes, not its name)."""


class EmptyRecordingError(RecordingError):
    """The file is empty (0 bytes), or the recording holds no message."""


class CorruptRecordingError(RecordingError):
    """The file looks like a recording but cannot be decoded (truncated, damaged, unsafe)."""


class NoPointCloudError(RecordingError):
    """The recording has no `sensor_msgs/PointCloud2` topic (or none of the configured ones)."""


class LidarTopicsError(RecordingError):
    """The PointCloud2 topics do not map one to one onto LiDAR frames (shared or empty frame)."""


class LidarPacketsError(NoPointCloudError):
    """The recording holds raw LiDAR packets (driver messages) but no PointCloud2 to read."""


class TooFewLidarsError(RecordingError):
    """Fewer than two LiDARs: there is nothing to calibrate against the reference."""


class NoTrajectoryError(RecordingError):
    """Neither the odometry topic nor `/tf` gives the `odom -> base` trajectory."""


class MissingExtrinsicsError(RecordingError):
    """A LiDAR has no initial `T_base_lidar`: no `/tf_static` chain and none in the config."""


class NoStopsError(RecordingError):
    """The trajectory never stands still long enough to accumulate a stop cloud."""


class EmptyStopCloudError(RecordingError):
    """A LiDAR has no valid point in one of the stops."""
