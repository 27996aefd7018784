"""How far a local surface fit settles noisy points off the surface they sample, measured on the
recording's own surfaces (a parametric bootstrap), so that segmentation can take it back.

A quadric fitted to a patch of points with range noise along the beams does not sit on the
surface: noise in the patch's in-plane coordinates flattens the fitted curvature, and the fit
then settles behind a convex surface (3-8 mm on a 15 cm cylinder under 2-3 cm of range noise,
`tests/bench/bench_surface_bias.py`). The offset depends on the surface's shape, the sampling
and the noise, all of which the recording shows: the smoothed points stand in for the surface,
the range noise is what smoothing took away from the raw points, and the same fit run on the
smoothed points with that noise added again shows how far it settles off them.

Each draw of noise is used twice, with both signs (antithetic): a fit's response to the noise
itself is odd in it and cancels, the bias is even and stays, so one pair of fits measures it
without the scatter of the noise. What is left is averaged over each point's patch.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from pykdtree.kdtree import KDTree

from pipeline.transforms import Points

Fit = Callable[[Points], Points]
"""A surface fit of points (N, 3) in the sensor's frame: where each point settles (N, 3)."""

MIN_NOISE_SAMPLES = 30
"""Fewer points seen within 60 deg of their normal than this: the noise is not measured, no
offset is reported (zeros)."""


def beams_to(points: Points) -> Points:
    """(N, 3) unit directions from the sensor (at the origin) to `points`."""
    ranges = np.linalg.norm(points, axis=1, keepdims=True)
    unit: Points = points / np.maximum(ranges, 1e-12)
    return unit


def range_noise_from_smoothing(
    raw: Points, smoothed: Points, normals: Points, beams: Points | None = None
) -> float | None:
    """The range noise (m, one sigma, robust) that the smoothing removed: each point's move along
    its normal divided by the cosine between normal and beam, over the points seen within 60 deg
    of their normal (a grazing beam turns a small move into a large range). None with fewer than
    `MIN_NOISE_SAMPLES` such points. `beams`: default, the directions to `smoothed`."""
    if beams is None:
        beams = beams_to(smoothed)
    cos = np.abs(np.einsum("ni,ni->n", normals, beams))
    facing = cos >= 0.5
    if np.count_nonzero(facing) < MIN_NOISE_SAMPLES:
        return None
    ranges = np.einsum("ni,ni->n", raw - smoothed, normals)[facing] / cos[facing]
    deviation = np.abs(ranges - np.median(ranges))
    return float(1.4826 * np.median(deviation))


def smoothing_offsets(
    raw: Points,
    smoothed: Points,
    normals: Points,
    fit: Fit,
    patch: int,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """(N,) how far (m) the surface fit `fit` settles each point along its normal (positive: the
    way `normals` point) from the surface the points sample, for points `raw` (N, 3, the sensor
    at the origin) that `fit` took to `smoothed` with `normals`. Zeros where the noise cannot be
    measured (see `range_noise_from_smoothing`) or the cloud is smaller than a patch."""
    offsets = np.zeros(len(raw))
    if len(raw) <= patch:
        return offsets
    beams = beams_to(smoothed)
    sigma = range_noise_from_smoothing(raw, smoothed, normals, beams)
    if sigma is None or sigma == 0.0:
        return offsets
    noise = beams * rng.normal(0.0, sigma, len(raw))[:, None]
    for sign in (1.0, -1.0):
        offsets += np.einsum("ni,ni->n", fit(smoothed + sign * noise) - smoothed, normals)
    offsets /= 2.0
    _, index = KDTree(smoothed).query(smoothed, k=patch)
    averaged: NDArray[np.float64] = offsets[np.asarray(index, dtype=np.int64)].mean(axis=1)
    return averaged
