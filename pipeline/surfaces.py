"""Local surface fits of point clouds: each point's plane from its nearest neighbours.

Shared by segmentation (which smooths object points and drops the ones seen edge-on) and by the
optimiser (normals for the point-to-plane residual).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TypedDict, Unpack

import numpy as np
from numpy.typing import NDArray
from pykdtree.kdtree import KDTree

from pipeline.transforms import Points


class SurfaceOptions(TypedDict, total=False):
    """How `local_planes` and `local_surfaces` fit each patch (see `local_planes`)."""

    quadric: bool
    along_beams: bool
    normals_along_beams: bool
    passes: int


def local_planes(
    points: Points,
    neighbours: int,
    centre_neighbours: int | None = None,
    **options: Unpack[SurfaceOptions],
) -> tuple[Points, Points]:
    """Each point projected onto its local surface, and that surface's unit normal there:
    (N, 3), (N, 3).

    The plane's normal is the least-spread direction of the `neighbours` nearest points; the plane
    goes through the centroid of the `centre_neighbours` nearest (all `neighbours` when None). The
    projection removes the range noise across the surface while keeping the sampling along it;
    without it the nearest noisy neighbour is biased towards the query point, which shrinks every
    residual and makes the iterations crawl. A smaller centring patch flattens curved surfaces
    (cylinders, capsules) less: the flattening depends on the viewpoint and biases the fit.

    `quadric=True` (moving least squares of degree 2) does not flatten at all: over the same
    neighbours, heights above the plane through the point are fitted with a quadratic in the
    plane's coordinates; the point moves to the fitted height and takes the fitted surface's
    normal there (`centre_neighbours` is then unused). Needs `neighbours` >= 10.

    `along_beams=True` (with `quadric`; the sensor at the origin) also fits the heights along
    each point's beam instead of along the plane's normal, and moves the point along its beam
    (the normal stays the one fitted along the plane's): a LiDAR's noise is in range only, so
    the heights then carry all of it. Under 30 mm of range noise, fitted along the normal the
    points of seed 1000 (rate 0.3) lay 3-5 mm behind the true surfaces along their beams,
    along the beams within 0.5 mm (the dense LiDARs; `tests/bench/bench_surface_bias.py`).

    `normals_along_beams=True` (the sensor at the origin) takes each normal from the plane
    fitted along the point's beam instead of the patch's least-spread direction: the n that
    minimises n^T C n with n . b = 1 (C the patch's scatter, b the unit beam), i.e. C^-1 b. Range
    noise spreads a patch along the beam, adding ~k sigma^2 b b^T to C; the least-spread
    direction then tilts away from the beam by ~sigma^2 (n.b)(t.b) / lambda_t (lambda_t the
    patch's spread along the surface: the smaller the patch, the larger the tilt), while
    C^-1 b, whose residuals are distances along the beam, is not tilted by it (noise-free
    regressors: errors-in-variables only in the heights).

    `passes` > 1 projects the projected points again, over the same neighbourhoods, each pass
    starting from where the last left them (moving least squares iterated towards its fixed
    point, the MLS surface). One pass moves a point only part of the way where range noise
    tilts and shifts its patch's frame, so under heavy noise the projected points still form a
    sheet several millimetres thick; every further pass thins it (see `SegmentationConfig`).
    """
    surfaces = local_surfaces(points, neighbours, centre_neighbours, **options)
    return surfaces.projected, surfaces.normals


@dataclass(frozen=True)
class LocalSurfaces:
    """`local_planes`' projections (N, 3) and normals (N, 3), and `along_normals` (N, 3): where
    the points were moved along their beams onto quadrics (`quadric`, `along_beams`, one pass,
    not `normals_along_beams`), where the quadric fitted along each patch's normal put them on
    the way: exactly what `quadric=True` alone returns, with the same normals. None
    otherwise."""

    projected: Points
    normals: Points
    along_normals: Points | None = None


def local_surfaces(
    points: Points,
    neighbours: int,
    centre_neighbours: int | None = None,
    *,
    quadric: bool = False,
    along_beams: bool = False,
    normals_along_beams: bool = False,
    passes: int = 1,
) -> LocalSurfaces:
    """`local_planes` (which see), keeping the quadric's projection along the normals that the
    beam quadric computes on the way (`LocalSurfaces.along_normals`): both surface models from
    one fit, for a caller that compares them."""
    if len(points) < 3:
        return LocalSurfaces(points.copy(), np.tile(np.array([0.0, 0.0, 1.0]), (len(points), 1)))
    k = min(neighbours, len(points))
    _, idx = KDTree(points).query(points, k=k)
    surfaces = LocalSurfaces(points, np.zeros_like(points))
    fit = _Fit(centre_neighbours, quadric, along_beams, normals_along_beams)
    for _ in range(max(passes, 1)):
        surfaces = _project(surfaces.projected, idx, fit)
    return surfaces if passes <= 1 else dataclasses.replace(surfaces, along_normals=None)


ROWS_PER_CHUNK = 2048
"""Points fitted together: their (rows, k) temporaries (1.3 MB each at k = 80) stay in the
cache, where a whole cloud's spill to memory at every one of the fit's ~40 array operations."""


@dataclass(frozen=True)
class _Fit:
    """How each point's surface is fitted (the arguments of `local_surfaces`)."""

    centre_neighbours: int | None
    quadric: bool
    along_beams: bool
    normals_along_beams: bool


def _project(cloud: Points, idx: NDArray[np.integer], fit: _Fit) -> LocalSurfaces:
    """One pass of `local_planes` over the neighbourhoods `idx` (N, k) of the points of `cloud`
    (N, 3), `ROWS_PER_CHUNK` points at a time (each point's fit is its own)."""
    chunks = [
        _project_rows(
            cloud, slice(start, start + ROWS_PER_CHUNK), idx[start : start + ROWS_PER_CHUNK], fit
        )
        for start in range(0, len(cloud), ROWS_PER_CHUNK)
    ]
    along = [chunk.along_normals for chunk in chunks if chunk.along_normals is not None]
    return LocalSurfaces(
        np.concatenate([chunk.projected for chunk in chunks]),
        np.concatenate([chunk.normals for chunk in chunks]),
        np.concatenate(along) if len(along) == len(chunks) else None,
    )


def _project_rows(cloud: Points, rows: slice, idx: NDArray[np.integer], fit: _Fit) -> LocalSurfaces:
    """`_project` for the points `cloud[rows]`, whose neighbourhoods in `cloud` are `idx`."""
    points = cloud[rows]
    k = idx.shape[1]
    centre_neighbours, quadric = fit.centre_neighbours, fit.quadric
    along_beams, normals_along_beams = fit.along_beams, fit.normals_along_beams
    # One contiguous (N, k) array per axis: strided views of an (N, k, 3) gather are slower.
    x, y, z = (cloud[:, axis][idx] for axis in range(3))
    centroid = np.column_stack([x.mean(axis=1), y.mean(axis=1), z.mean(axis=1)])
    x -= centroid[:, 0:1]
    y -= centroid[:, 1:2]
    z -= centroid[:, 2:3]
    covariance = np.empty((len(points), 3, 3))
    covariance[:, 0, 0] = np.einsum("nk,nk->n", x, x)
    covariance[:, 1, 1] = np.einsum("nk,nk->n", y, y)
    covariance[:, 2, 2] = np.einsum("nk,nk->n", z, z)
    covariance[:, 0, 1] = covariance[:, 1, 0] = np.einsum("nk,nk->n", x, y)
    covariance[:, 0, 2] = covariance[:, 2, 0] = np.einsum("nk,nk->n", x, z)
    covariance[:, 1, 2] = covariance[:, 2, 1] = np.einsum("nk,nk->n", y, z)
    if along_beams or normals_along_beams:
        beams = points / np.maximum(np.linalg.norm(points, axis=1, keepdims=True), 1e-12)
    normals = (
        _normals_along_beams(covariance, beams)
        if normals_along_beams
        else smallest_eigenvectors(covariance)
    )
    if quadric and k >= 10:
        # The neighbours seen from the point, (N, k, 3): both fits below share them.
        offsets = cloud[idx] - points[:, None, :]
        projected, fitted = _quadric_surfaces(offsets, points, normals)
        kept = normals if normals_along_beams else fitted
        if along_beams:
            # Only where the point goes: the normal from a quadric fitted along a beam has six
            # coefficients to spend on a patch seen on one or two scan lines.
            along_normals = None if normals_along_beams else projected
            projected, _ = _quadric_surfaces(offsets, points, beams)
            return LocalSurfaces(projected, kept, along_normals)
        return LocalSurfaces(projected, kept)
    if centre_neighbours is not None and centre_neighbours < k:
        # pykdtree returns the neighbours nearest first.
        near = idx[:, :centre_neighbours]
        centroid = np.column_stack([cloud[:, axis][near].mean(axis=1) for axis in range(3)])
    offset = np.einsum("ni,ni->n", normals, points - centroid)
    return LocalSurfaces(points - offset[:, None] * normals, normals)


def _normals_along_beams(covariance: NDArray[np.float64], beams: Points) -> Points:
    """(N, 3) unit normals C^-1 b of the planes fitted along the unit `beams` (N, 3) to the
    patches of scatter `covariance` (N, 3, 3)."""
    # A ridge far below any patch's spread keeps a noise-free plane (C singular along its normal,
    # where C^-1 b points) solvable.
    ridge = 1e-12 * (1.0 + np.trace(covariance, axis1=1, axis2=2))[:, None, None] * np.eye(3)
    normals = np.linalg.solve(covariance + ridge, beams[:, :, None])[:, :, 0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return normals


def _quadric_surfaces(
    offsets: NDArray[np.float64], points: Points, normals: Points
) -> tuple[Points, Points]:
    """Project each point (N, 3) onto `h = c0 + c1 a + c2 b + c3 a^2 + c4 ab + c5 b^2`, fitted by
    least squares to its k neighbours, `offsets` (N, k, 3) from the point, in the frame (h along
    the unit `normals` (N, 3), a, b across them) centred at the point, along `normals`; return
    the projections and the fitted surface's unit normals there."""
    # Any orthonormal tangent pair will do: the full quadratic does not depend on its rotation.
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normals, u)
    frame = np.stack([u, v, normals], axis=2)  # (N, 3, 3): columns a, b, h
    local = np.matmul(offsets, frame)  # (N, k, 3)
    a, b, h = local[:, :, 0], local[:, :, 1], local[:, :, 2]
    gram, moment_h = _quadric_normal_equations(a, b, h)
    # A tiny ridge keeps degenerate patches (collinear neighbours) solvable.
    gram += 1e-9 * np.eye(6)
    coefficients = np.linalg.solve(gram, moment_h[:, :, None])[:, :, 0]
    projected = points + coefficients[:, :1] * normals
    fitted = normals - coefficients[:, 1:2] * u - coefficients[:, 2:3] * v
    fitted /= np.linalg.norm(fitted, axis=1, keepdims=True)
    return projected, fitted


def _quadric_normal_equations(
    a: NDArray[np.float64], b: NDArray[np.float64], h: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The least-squares normal equations (N, 6, 6) and right-hand sides (N, 6) of
    `h = c0 + c1 a + c2 b + c3 a^2 + c4 ab + c5 b^2` over k samples (N, k) each. The Gram
    matrix holds only the 15 moments `sum a^i b^j` (i + j <= 4), each summed once: a third of
    the work of forming every product of the (N, k, 6) design matrix."""
    aa, ab, bb = a * a, a * b, b * b
    powers = {(0, 0): np.ones_like(a), (1, 0): a, (0, 1): b, (2, 0): aa, (1, 1): ab, (0, 2): bb}
    powers.update({(3, 0): aa * a, (2, 1): aa * b, (1, 2): a * bb, (0, 3): bb * b})
    powers.update({(4, 0): aa * aa, (3, 1): aa * ab, (2, 2): aa * bb, (1, 3): ab * bb})
    powers[(0, 4)] = bb * bb
    moments = {key: value.sum(axis=1) for key, value in powers.items()}
    terms = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))
    gram = np.empty((len(a), 6, 6))
    for row, (i1, j1) in enumerate(terms):
        for col, (i2, j2) in enumerate(terms[row:], start=row):
            gram[:, row, col] = gram[:, col, row] = moments[(i1 + i2, j1 + j2)]
    rhs = np.stack([h.sum(axis=1)] + [(powers[term] * h).sum(axis=1) for term in terms[1:]], axis=1)
    return gram, rhs


def smallest_eigenvectors(covariance: NDArray[np.float64]) -> Points:
    """(N, 3) unit eigenvectors of the smallest eigenvalue of symmetric (N, 3, 3) matrices.

    Closed form (trigonometric eigenvalues, then a cross product of two rows of A - lambda I):
    a batched `eigh` costs ten times as much for the same answer.
    """
    A = covariance
    q = np.trace(A, axis1=1, axis2=2) / 3.0
    p1 = A[:, 0, 1] ** 2 + A[:, 0, 2] ** 2 + A[:, 1, 2] ** 2
    p2 = (A[:, 0, 0] - q) ** 2 + (A[:, 1, 1] - q) ** 2 + (A[:, 2, 2] - q) ** 2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe_p = np.where(p > 1e-300, p, 1.0)
    B = (A - q[:, None, None] * np.eye(3)) / safe_p[:, None, None]
    r = np.clip(np.linalg.det(B) / 2.0, -1.0, 1.0)
    smallest = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
    M = A - smallest[:, None, None] * np.eye(3)
    candidates = np.stack(
        [np.cross(M[:, 0], M[:, 1]), np.cross(M[:, 0], M[:, 2]), np.cross(M[:, 1], M[:, 2])], axis=1
    )
    norms = np.linalg.norm(candidates, axis=2)
    best = np.argmax(norms, axis=1)
    rows = np.arange(len(A))
    vectors = candidates[rows, best]
    length = norms[rows, best]
    # An isotropic neighbourhood has no preferred normal; any unit vector is as good.
    vectors[length < 1e-300] = (0.0, 0.0, 1.0)
    length[length < 1e-300] = 1.0
    result: Points = vectors / length[:, None]
    return result


def orient_towards_origin(points: Points, normals: Points) -> Points:
    """`normals` (N, 3) flipped where needed to face the origin (the sensor) from `points`."""
    flip = np.einsum("ni,ni->n", normals, points) > 0
    result: Points = np.where(flip[:, None], -normals, normals)
    return result
