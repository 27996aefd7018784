"""Decode `sensor_msgs/PointCloud2` into (N, 3) float64 points, vectorised from its fields.

Any `point_step` and row padding, float32 or float64 `x, y, z` at any offsets, either byte order;
other fields are ignored and points with a NaN or infinite coordinate are dropped.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.io.errors import CorruptRecordingError

# sensor_msgs/PointField datatype codes -> numpy kinds (only floats make sense for coordinates).
_FLOAT_TYPES = {7: "f4", 8: "f8"}
_FIELD_NAMES = {
    1: "int8",
    2: "uint8",
    3: "int16",
    4: "uint16",
    5: "int32",
    6: "uint32",
    7: "float32",
    8: "float64",
}


def point_count(msg: Any) -> int:
    """How many points (valid or not) the message carries: `width * height`."""
    return int(msg.width) * int(msg.height)


def xyz_dtype(msg: Any, topic: str) -> np.dtype[Any]:
    """A structured dtype viewing one point record of `msg` as its `x, y, z` fields.

    Raises `CorruptRecordingError` if a coordinate is missing, not a float, or outside the record.
    """
    fields = {field.name: field for field in msg.fields}
    order = ">" if msg.is_bigendian else "<"
    step = int(msg.point_step)
    formats: list[str] = []
    offsets: list[int] = []
    for name in ("x", "y", "z"):
        field = fields.get(name)
        if field is None:
            raise CorruptRecordingError(
                f"PointCloud2 on {topic} has no {name!r} field (fields: {sorted(fields)}); "
                "LiDAR clouds must carry float32 or float64 x, y, z"
            )
        kind = _FLOAT_TYPES.get(int(field.datatype))
        if kind is None:
            found = _FIELD_NAMES.get(int(field.datatype), f"datatype {field.datatype}")
            raise CorruptRecordingError(
                f"PointCloud2 on {topic} stores {name!r} as {found}; "
                "LiDAR clouds must carry float32 or float64 x, y, z"
            )
        if int(field.offset) + int(kind[1]) > step:
            raise CorruptRecordingError(
                f"PointCloud2 on {topic}: field {name!r} at offset {field.offset} does not fit in "
                f"point_step {step}; the message is damaged"
            )
        formats.append(order + kind)
        offsets.append(int(field.offset))
    return np.dtype(
        {"names": ["x", "y", "z"], "formats": formats, "offsets": offsets, "itemsize": step}
    )


def decode_xyz(msg: Any, topic: str, *, drop_zero_points: bool = True) -> NDArray[np.float64]:
    """The message's valid points, (N, 3) float64 in its `header.frame_id`.

    Drops points with a NaN or infinite coordinate, and with `drop_zero_points` points exactly at
    the origin (the no-return marker of several drivers).
    """
    dtype = xyz_dtype(msg, topic)
    width, height = int(msg.width), int(msg.height)
    count = width * height
    if count == 0:
        return np.empty((0, 3))
    step, row_step = int(msg.point_step), int(msg.row_step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if row_step < width * step or data.size < (height - 1) * row_step + width * step:
        raise CorruptRecordingError(
            f"PointCloud2 on {topic} holds {data.size} bytes, too few for {height} x {width} "
            f"points of {step} bytes (row_step {row_step}); the message is truncated or damaged"
        )
    if row_step == width * step:
        records = np.frombuffer(data, dtype=dtype, count=count)
    else:
        # Padded rows: view each row's used prefix, then flatten.
        rows = np.lib.stride_tricks.as_strided(
            data, shape=(height, width * step), strides=(row_step, 1)
        )
        records = np.ascontiguousarray(rows).reshape(-1).view(dtype)
    points = np.empty((count, 3))
    points[:, 0] = records["x"]
    points[:, 1] = records["y"]
    points[:, 2] = records["z"]
    valid = np.isfinite(points).all(axis=1)
    if drop_zero_points:
        valid &= points.any(axis=1)
    return points if valid.all() else points[valid]
