"""PointCloud2 decoding from the message's own fields: layouts, byte orders, invalid points."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from pipeline.io.errors import CorruptRecordingError
from pipeline.io.pointcloud import decode_xyz, point_count
from pipeline.io.typestores import ros2_typestore

_CODES = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}


def cloud_msg(records: Any, *, height: int = 1, row_padding: int = 0) -> Any:
    """A PointCloud2 whose fields, offsets and byte order are those of `records`' dtype."""
    types = ros2_typestore().types
    dtype: Any = records.dtype
    big = any(dtype.fields[name][0].byteorder == ">" for name in dtype.names)
    fields = [
        types["sensor_msgs/msg/PointField"](
            name=name, offset=offset, datatype=_CODES[sub.str[1:]], count=1
        )
        for name, (sub, offset) in dtype.fields.items()
    ]
    width = len(records) // height
    rows = records.view(np.uint8).reshape(height, width * dtype.itemsize)
    data = np.concatenate([rows, np.zeros((height, row_padding), np.uint8)], axis=1).reshape(-1)
    header = types["std_msgs/msg/Header"](
        stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="lidar"
    )
    return types["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=height,
        width=width,
        fields=fields,
        is_bigendian=big,
        point_step=dtype.itemsize,
        row_step=width * dtype.itemsize + row_padding,
        data=data,
        is_dense=False,
    )


def _records(points: Any, spec: Any) -> Any:
    records: Any = np.zeros(len(points), dtype=np.dtype(spec))
    for axis, name in enumerate("xyz"):
        records[name] = points[:, axis]
    return records


POINTS = np.random.default_rng(3).uniform(-20, 20, (12, 3))


@pytest.mark.parametrize(
    "spec",
    [
        # float32 with intensity and padding: the common LiDAR driver layout
        {
            "names": ["x", "y", "z", "intensity"],
            "formats": ["<f4"] * 4,
            "offsets": [0, 4, 8, 16],
            "itemsize": 32,
        },
        # float64, big-endian, fields stored z, y, x
        {"names": ["z", "y", "x"], "formats": [">f8"] * 3, "offsets": [0, 8, 16], "itemsize": 24},
        # mixed widths and an odd point_step with a ring index between coordinates
        {
            "names": ["ring", "x", "y", "z"],
            "formats": ["<u2", "<f8", "<f4", "<f8"],
            "offsets": [0, 2, 10, 14],
            "itemsize": 23,
        },
    ],
)
def test_layouts_decode_to_the_same_points(spec: dict[str, Any]) -> None:
    msg = cloud_msg(_records(POINTS, spec))

    points = decode_xyz(msg, "/t")

    assert points.dtype == np.float64 and points.shape == (12, 3)
    np.testing.assert_allclose(points, POINTS, atol=1e-5)  # float32 rounding of |p| <= 35 m


def test_padded_rows_of_an_organised_cloud() -> None:
    spec = {"names": ["x", "y", "z"], "formats": ["<f8"] * 3}
    msg = cloud_msg(_records(POINTS, spec), height=3, row_padding=5)

    assert point_count(msg) == 12
    np.testing.assert_array_equal(decode_xyz(msg, "/t"), POINTS)


def test_nan_inf_and_origin_points_are_dropped() -> None:
    points = POINTS.copy()
    points[1, 0] = np.nan
    points[4, 2] = np.inf
    points[7] = 0.0
    msg = cloud_msg(_records(points, {"names": ["x", "y", "z"], "formats": ["<f8"] * 3}))

    np.testing.assert_array_equal(decode_xyz(msg, "/t"), np.delete(POINTS, [1, 4, 7], axis=0))
    kept_origin = decode_xyz(msg, "/t", drop_zero_points=False)
    assert len(kept_origin) == 10 and (kept_origin == 0).all(axis=1).sum() == 1


def test_empty_cloud() -> None:
    msg = cloud_msg(_records(POINTS[:0], {"names": ["x", "y", "z"], "formats": ["<f4"] * 3}))
    assert decode_xyz(msg, "/t").shape == (0, 3)


def test_missing_coordinate_field() -> None:
    msg = cloud_msg(np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4"), ("intensity", "<f4")]))
    with pytest.raises(CorruptRecordingError, match=r"/t has no 'z' field .*float32 or float64"):
        decode_xyz(msg, "/t")


def test_integer_coordinates_are_refused() -> None:
    msg = cloud_msg(np.zeros(3, dtype=[("x", "<u2"), ("y", "<f4"), ("z", "<f4")]))
    with pytest.raises(CorruptRecordingError, match=r"stores 'x' as uint16"):
        decode_xyz(msg, "/t")


def test_field_outside_the_point_record() -> None:
    msg = cloud_msg(np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")]))
    msg.point_step = 10
    with pytest.raises(CorruptRecordingError, match=r"field 'z' at offset 8 does not fit"):
        decode_xyz(msg, "/t")


def test_truncated_data() -> None:
    msg = cloud_msg(np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")]))
    msg.data = msg.data[:-1]
    with pytest.raises(CorruptRecordingError, match=r"holds 35 bytes, too few for 1 x 3 points"):
        decode_xyz(msg, "/t")
