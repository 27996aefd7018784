"""Global alignment: a search over the planar degrees of freedom that stage 3 leaves, before
stage 4's local refinement (issue 13: convergence from initial errors up to 0.5 m / 15 deg).

After stage 3 every LiDAR's roll, pitch and height over the floor are right; what is left is,
per LiDAR, a rotation about the floor's normal and a shift along the floor. Stage 4 pairs each
point with its nearest neighbour, so from a start further off than the objects' spacing it can
settle on a wrong match (on a back-and-forth lane, a LiDAR one stop spacing along the lane: every
object lands on the next one). Here the whole planar range is scored instead:

Each other LiDAR's extrinsic relative to the reference (`E`, planar in the reference frame) is
searched: its object points placed with `T_G_ref[j] @ E @ T_ref_lidar` and counted where the
reference's map is occupied. The stop poses stay as stage 3 left them: a search of the
reference's own planar extrinsic (the hand-eye problem a wrong one poses, smearing the
reference's map wherever the robot turned) was tried, scoring how well the reference's stops
agree with each other, and dropped: on routines that mostly drive straight its yaw is seen only
through the drives' lengths, and on a synthetic scene and on seed 1020 it moved the reference the
wrong way.

The search is exhaustive on a coarse grid (rotation and shift), then finer around the best few. A
candidate replaces the current estimate only where it scores `min_gain` times the current one:
flat scores (the data cannot tell) keep what stage 3 left, and stage 4 refines either way.
Every count is on the floor plane (2-D), because stage 3 has fixed the rest.

Frames: G is the reference's frame at stop 0 (floor normal `n_G` there), `ref` the reference
LiDAR's frame; a planar transform in `ref` rotates about `n_ref` (the floor normal seen from the
reference) and shifts along the floor.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from pipeline.geometry import Plane, tangent_basis
from pipeline.transforms import Matrix4, Points

_FROZEN = ConfigDict(frozen=True, extra="forbid")


class GlobalAlignmentConfig(BaseModel):
    """The planar search before stage 4; lengths in metres, angles in degrees."""

    model_config = _FROZEN

    enabled: bool = Field(
        default=True,
        description="the planar search runs between stages 3 and 4 (on since `choose: refined` "
        "became the default: see docs/method.md for the randomised benchmark behind it)",
    )
    max_translation_m: float = Field(
        default=1.0,
        gt=0,
        description="half-width of the shifts searched: two extrinsics each off by 0.5 m put "
        "one LiDAR up to 1 m from the reference",
    )
    max_rotation_deg: float = Field(default=30.0, gt=0, le=180)
    cell_m: float = Field(
        default=0.1, gt=0, description="cells of the floor plane in which maps are counted"
    )
    coarse_rotation_step_deg: float = Field(default=4.0, gt=0)
    fine_rotation_step_deg: float = Field(default=1.0, gt=0)
    points_per_cloud: int = Field(
        default=60, ge=10, description="random object points per (LiDAR, stop) cloud scored"
    )
    min_gain: float = Field(
        default=1.25,
        ge=1.0,
        description="a candidate replaces the current estimate only where it scores this many "
        "times as high",
    )
    choose: Literal["score", "refined"] = Field(
        default="refined",
        description="score: the candidates that score min_gain times as high replace the "
        "estimate before stage 4; refined: they become a second start instead, stage 4 runs "
        "from both and keeps the solution with the smaller metric error (eq. 12): a planar "
        "score on sampled points can prefer a wrong match that refinement shows for what it is",
    )
    seed: int = 0


@dataclass(frozen=True)
class PlanarMove:
    """A search's outcome: the rotation (deg) and shift (m, along the floor) found, and the
    scores of the current estimate and of the best candidate (counts of agreeing points)."""

    rotation_deg: float
    shift_m: tuple[float, float]
    score_current: float
    score_best: float
    adopted: bool


@dataclass(frozen=True)
class GlobalAlignmentResult:
    """Poses after the search (`T_G_ref` (J, 4, 4), unchanged; `T_ref_lidar` (L, 4, 4)) and
    its move of each non-reference LiDAR, in order."""

    T_G_ref: NDArray[np.float64]
    T_ref_lidar: NDArray[np.float64]
    moves: tuple[PlanarMove, ...]


@dataclass(frozen=True)
class _Plane2D:
    """The floor's coordinates: `basis_ref` (3, 2) along the floor in the reference frame (right
    handed with `n_ref`), `Q` (J, 2, 2) each stop's rotation of those coordinates into G's floor
    coordinates, `c` (J, 2) where each stop's reference origin lands there."""

    basis_ref: NDArray[np.float64]
    Q: NDArray[np.float64]
    c: NDArray[np.float64]


def _plane_2d(T_G_ref: NDArray[np.float64], floor_G: Plane) -> _Plane2D:
    basis_G = tangent_basis(floor_G.normal)
    n_ref = T_G_ref[0, :3, :3].T @ floor_G.normal
    basis_ref = tangent_basis(n_ref)
    Q = np.einsum("ia,jik,kb->jab", basis_G, T_G_ref[:, :3, :3], basis_ref)
    c = T_G_ref[:, :3, 3] @ basis_G
    return _Plane2D(basis_ref, Q, c)


def _planar_transform(plane: _Plane2D, rotation_deg: float, shift: NDArray[np.float64]) -> Matrix4:
    """The transform in the reference frame: a rotation about `n_ref`, a shift along the floor."""
    basis = plane.basis_ref
    normal = np.cross(basis[:, 0], basis[:, 1])
    R2 = _rotations(np.array([rotation_deg]))[0]
    T = np.eye(4)
    T[:3, :3] = basis @ R2 @ basis.T + np.outer(normal, normal)
    T[:3, 3] = basis @ shift
    return T


def _rotations(psi_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    angle = np.radians(psi_deg)
    cos, sin = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], -2)


@dataclass(frozen=True)
class _Cloud2D:
    """Sampled points of one LiDAR in the floor coordinates of the reference frame (`a`, (N, 2))
    and the stop of each (N,)."""

    a: NDArray[np.float64]
    stop: NDArray[np.int64]


def _sample(
    clouds: Sequence[Points],
    T_ref_lidar: Matrix4,
    plane: _Plane2D,
    count: int,
    rng: np.random.Generator,
) -> _Cloud2D:
    rows, stops = [], []
    for stop, points in enumerate(clouds):
        if len(points) == 0:
            continue
        pick = rng.choice(len(points), size=min(count, len(points)), replace=False)
        in_ref = points[pick] @ T_ref_lidar[:3, :3].T + T_ref_lidar[:3, 3]
        rows.append(in_ref @ plane.basis_ref)
        stops.append(np.full(len(pick), stop, dtype=np.int64))
    if not rows:
        return _Cloud2D(np.zeros((0, 2)), np.zeros(0, dtype=np.int64))
    return _Cloud2D(np.concatenate(rows), np.concatenate(stops))


def _placed(
    cloud: _Cloud2D, plane: _Plane2D, psi_deg: float, shifts: NDArray[np.float64]
) -> NDArray[np.float32]:
    """(S, N, 2): the points in G's floor coordinates for the rotation `psi_deg` and every shift
    of `shifts` (S, 2): u = Q_j (R(psi) a + t) + c_j."""
    rotated = cloud.a @ _rotations(np.array([psi_deg]))[0].T
    Q = plane.Q[cloud.stop]  # (N, 2, 2)
    base = np.einsum("nab,nb->na", Q, rotated) + plane.c[cloud.stop]
    out = np.empty((len(shifts), len(base), 2), dtype=np.float32)
    for axis in range(2):
        out[..., axis] = (
            base[:, axis]
            + shifts[:, :1] * Q[:, axis, 0][None, :]
            + shifts[:, 1:] * Q[:, axis, 1][None, :]
        )
    return out


@dataclass(frozen=True)
class _Grid:
    """Occupied cells of the floor plane, one cell's margin around them."""

    origin: NDArray[np.float64]
    cell: float
    occupied: NDArray[np.bool_]

    def count(self, u: NDArray[np.float32]) -> NDArray[np.float64]:
        """Points of `u` (..., N, 2) in occupied cells, per leading index. The grid's outermost
        cells are never occupied, so points beyond it are clipped onto them."""
        rows, cols = self.occupied.shape
        scaled = (u - self.origin.astype(np.float32)) / np.float32(self.cell)
        row = np.clip(scaled[..., 0], 0, rows - 1).astype(np.int32)
        col = np.clip(scaled[..., 1], 0, cols - 1).astype(np.int32)
        hit = self.occupied.ravel()[row * cols + col]
        result: NDArray[np.float64] = np.count_nonzero(hit, axis=-1).astype(np.float64)
        return result


def _grid(u: NDArray[np.float64], cell: float) -> _Grid:
    """The cells `u` (N, 2) occupy, dilated by one cell (a point near a cell's edge counts)."""
    origin = u.min(axis=0) - 3 * cell
    index = np.floor((u - origin) / cell).astype(np.int64)
    shape = tuple(int(n) for n in index.max(axis=0) + 4)
    occupied = np.zeros(shape, dtype=bool)
    occupied[index[:, 0], index[:, 1]] = True
    dilated = occupied.copy()
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            dilated |= np.roll(np.roll(occupied, dx, axis=0), dy, axis=1)
    return _Grid(origin, cell, dilated)  # two empty cells around: the clip's landing strip


@dataclass(frozen=True)
class _Scorer:
    """Scores of candidates (rotations (P,), shifts (S, 2)) as (P, S): `cloud` placed with each,
    then `judge` (the (S, N, 2) placed points of one rotation -> (S,) scores)."""

    cloud: _Cloud2D
    plane: _Plane2D
    judge: Callable[[NDArray[np.float32]], NDArray[np.float64]]

    def __call__(
        self, psi: NDArray[np.float64], shifts: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        out = np.empty((len(psi), len(shifts)))
        for p in range(len(psi)):
            out[p] = self.judge(_placed(self.cloud, self.plane, float(psi[p]), shifts))
        return out


def _search(
    score: _Scorer, config: GlobalAlignmentConfig
) -> tuple[float, NDArray[np.float64], float, float]:
    """Best (rotation deg, shift (2,)) on a coarse grid, then a finer one around the best few;
    with the score of the current estimate and of the best."""
    cell = config.cell_m
    half = config.max_translation_m
    coarse = np.arange(-half, half + 1e-9, cell)
    shifts = np.stack(np.meshgrid(coarse, coarse, indexing="ij"), -1).reshape(-1, 2)
    psi = np.arange(
        -config.max_rotation_deg, config.max_rotation_deg + 1e-9, config.coarse_rotation_step_deg
    )
    scores = score(psi, shifts)  # (P, S)
    current = float(score(np.zeros(1), np.zeros((1, 2)))[0, 0])
    best_psi, best_shift, best = 0.0, np.zeros(2), current
    for flat in np.argsort(scores, axis=None)[::-1][:3]:
        p, s = np.unravel_index(flat, scores.shape)
        step = config.coarse_rotation_step_deg
        fine_psi = psi[p] + np.arange(-step, step + 1e-9, config.fine_rotation_step_deg)
        offsets = np.arange(-cell, cell + 1e-9, cell / 4)
        fine_shifts = shifts[s] + np.stack(
            np.meshgrid(offsets, offsets, indexing="ij"), -1
        ).reshape(-1, 2)
        fine = score(fine_psi, fine_shifts)
        i, j = np.unravel_index(int(np.argmax(fine)), fine.shape)
        if fine[i, j] > best:
            best_psi, best_shift, best = float(fine_psi[i]), fine_shifts[j], float(fine[i, j])
    return best_psi, best_shift, current, best


def align_globally(
    objects: Sequence[Sequence[Points]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    floor_G: Plane,
    config: GlobalAlignmentConfig,
) -> GlobalAlignmentResult:
    """Search each non-reference LiDAR's planar extrinsic against the reference's map, as the
    module says. `objects[lidar][stop]`: object points (N, 3) in that LiDAR's frame, the
    reference first; `floor_G`: stage 3's floor."""
    rng = np.random.default_rng(config.seed)
    plane = _plane_2d(T_G_ref, floor_G)
    count = config.points_per_cloud
    reference = _sample(objects[0], np.eye(4), plane, count, rng)
    placed = _placed(reference, plane, 0.0, np.zeros((1, 2)))[0].astype(np.float64)
    grid = _grid(placed, config.cell_m) if len(placed) else None
    lidars = np.array(T_ref_lidar, dtype=np.float64)
    moves = []
    for lidar in range(1, len(objects)):
        cloud = _sample(objects[lidar], T_ref_lidar[lidar], plane, count, rng)
        if grid is None or len(cloud.a) == 0:
            moves.append(PlanarMove(0.0, (0.0, 0.0), 0.0, 0.0, False))
            continue
        psi, shift, current, best = _search(_Scorer(cloud, plane, grid.count), config)
        adopted = best >= config.min_gain * current and best > 0
        moves.append(PlanarMove(psi, (float(shift[0]), float(shift[1])), current, best, adopted))
        if adopted:
            lidars[lidar] = _planar_transform(plane, psi, shift) @ T_ref_lidar[lidar]
    return GlobalAlignmentResult(np.array(T_G_ref, dtype=np.float64), lidars, tuple(moves))
