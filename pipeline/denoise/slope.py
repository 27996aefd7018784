"""Whether a point lies on a smooth surface through its neighbouring beams, however slanted.

A surface seen at grazing incidence leaves a point few neighbours at its own range: their ranges
climb steadily across the view, nearer on one side and farther on the other, as a mixed return's
do. What tells them apart is the shape: on a surface the neighbours' range differences are a
linear function of their direction offsets (the range's gradient over the view) that passes
through the point; a mixed return's neighbours are a step, near surface on one side and far
surface on the other, which no plane through the point fits. So the range differences are
fitted by least squares as `a x + b y + c` over the neighbours' offsets `(x, y)` (radians, in the
plane perpendicular to the point's beam), and the point is on a smooth surface when the fit's
RMS residual and its intercept `c` (the point's own offset from the fitted surface, along its
beam) are both within `tau`, the range noise's threshold. No slope limit and no typical spread
per direction are needed: the gradient is whatever the data say.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.denoise.filters import Points

_FALLBACK_AXIS_COS = 0.9


def on_smooth_surface(
    units: Points, neighbour_units: NDArray[np.float64], range_diff: NDArray[np.float64], tau: float
) -> NDArray[np.bool_]:
    """(M,) True where the range differences `range_diff` (M, k, metres) of the neighbouring
    directions `neighbour_units` (M, k, 3) fit a plane through the point of unit direction
    `units` (M, 3) within `tau` (metres), as the module docstring says."""
    if len(units) == 0:
        return np.zeros(0, dtype=np.bool_)
    first, second = _tangent_axes(units)
    offsets = neighbour_units - units[:, None, :]
    design = np.stack(
        [
            np.einsum("mkj,mj->mk", offsets, first),
            np.einsum("mkj,mj->mk", offsets, second),
            np.ones(offsets.shape[:2]),
        ],
        axis=-1,
    )
    normal = np.einsum("mki,mkj->mij", design, design) + 1e-12 * np.eye(3)
    rhs = np.einsum("mki,mk->mi", design, range_diff)
    coefficients = np.linalg.solve(normal, rhs[..., None])[..., 0]
    residual = range_diff - np.einsum("mki,mi->mk", design, coefficients)
    rms = np.sqrt(np.mean(residual**2, axis=1))
    return np.asarray((rms <= tau) & (np.abs(coefficients[:, 2]) <= tau), dtype=np.bool_)


def _tangent_axes(units: Points) -> tuple[Points, Points]:
    """Two unit vectors perpendicular to each of `units` (M, 3) and to each other."""
    reference = np.where(
        np.abs(units[:, 2:3]) < _FALLBACK_AXIS_COS, np.array([[0.0, 0.0, 1.0]]), [[1.0, 0.0, 0.0]]
    )
    first = np.cross(units, reference)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    return first, np.cross(units, first)
