"""Property-based fuzzing of the PointCloud2 decoder: any message a damaged or hostile recording
can carry (fields, offsets, datatypes, steps, sizes and bytes drawn at random) either decodes to
finite (N, 3) points or raises a `PipelineError`; nothing else escapes."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.errors import PipelineError
from pipeline.io.pointcloud import decode_xyz, point_count

UINT32 = 2**32 - 1

names = st.sampled_from(["x", "y", "z", "intensity", "ring", "", "X"])
field = st.builds(
    SimpleNamespace,
    name=names,
    offset=st.one_of(st.integers(0, 40), st.integers(0, UINT32)),
    datatype=st.one_of(st.integers(0, 9), st.integers(0, 255)),
    count=st.integers(0, 3),
)


@st.composite
def messages(draw: st.DrawFn) -> SimpleNamespace:
    """A PointCloud2-shaped message: sometimes consistent, often not."""
    fields = draw(st.lists(field, max_size=6))
    if draw(st.booleans()):
        # Start from a plausible layout so that decoding gets past the field checks.
        size = draw(st.sampled_from([4, 8]))
        fields = [
            SimpleNamespace(name=n, offset=i * size, datatype=7 if size == 4 else 8, count=1)
            for i, n in enumerate("xyz")
        ] + fields
    small = st.integers(0, 64)
    width = draw(st.one_of(small, st.integers(0, UINT32)))
    height = draw(st.one_of(st.integers(0, 4), st.integers(0, UINT32)))
    point_step = draw(st.one_of(small, st.integers(0, UINT32)))
    row_step = draw(
        st.one_of(st.just(width * point_step), small, st.integers(0, UINT32), st.just(0))
    )
    data = draw(st.binary(max_size=2048))
    if draw(st.booleans()):
        # Enough bytes for the declared shape (when it is small): real float patterns, NaN and
        # infinities included.
        needed = min(max(height - 1, 0) * row_step + width * point_step, 4096)
        raw = draw(
            st.lists(
                st.floats(width=32, allow_nan=True, allow_infinity=True),
                min_size=needed // 4 + 1,
                max_size=needed // 4 + 1,
            )
        )
        data = np.asarray(raw, dtype="<f4").tobytes()[: max(needed, 0)]
    return SimpleNamespace(
        fields=fields,
        width=width,
        height=height,
        point_step=point_step,
        row_step=row_step,
        is_bigendian=draw(st.booleans()),
        data=np.frombuffer(data, dtype=np.uint8),
    )


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=messages(), drop_zero=st.booleans(), keep_type=st.booleans())
def test_any_message_decodes_to_finite_points_or_a_pipeline_error(
    msg: Any, drop_zero: bool, keep_type: bool
) -> None:
    dtype = None if keep_type else np.float64
    try:
        points = decode_xyz(msg, "/fuzz", drop_zero_points=drop_zero, dtype=dtype)
    except PipelineError:
        return
    assert points.ndim == 2 and points.shape[1] == 3
    assert len(points) <= point_count(msg)
    assert np.isfinite(points).all(), "NaN and infinite points are dropped"
    if drop_zero and len(points):
        assert (np.abs(points).sum(axis=1) > 0).all(), "origin points are dropped"
