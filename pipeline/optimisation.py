"""Stage 4: stop poses and extrinsics refined together on object points, like ICP.

Unknowns: `T_G_ref` per stop (stop 0 fixed: the gauge) and `T_ref_lidar` per non-reference LiDAR.
Each iteration places every object cloud in G, associates each point with its nearest neighbour
in the reference LiDAR's object map (kd-tree), and takes one Levenberg-Marquardt step on the
robust cost below, with the normal equations assembled in numpy:

- cross terms: points of LiDAR i at stop j against the reference map (eq. 11 of the paper);
- reference self-consistency: reference points at stop j against the reference map of the other
  stops, so the map the others are aligned to cannot bend;
- floor terms: every (LiDAR, stop) floor plane against the floor in G from stage 3, so the objects
  cannot trade roll, pitch or height for a slightly better fit.

Twists are `[rho (3), phi (3)]` applied on the left: `T_G_ref <- exp(d) T_G_ref` in G, and
`T_ref_lidar <- exp(e) T_ref_lidar` in the reference frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from pykdtree.kdtree import KDTree

from pipeline.geometry import Plane, adjoint, exp_se3, hat, plane_in_parent, tangent_basis
from pipeline.surfaces import local_planes, orient_towards_origin
from pipeline.transforms import Matrix4, Points

_FROZEN = ConfigDict(frozen=True, extra="forbid")

ResidualKind = Literal["point_to_point", "point_to_plane"]
RobustLoss = Literal["cauchy", "huber", "none"]


class OptimisationConfig(BaseModel):
    """The joint optimisation; lengths in metres, angles in degrees."""

    model_config = _FROZEN

    residual: ResidualKind = "point_to_plane"
    max_iterations: int = Field(default=200, ge=1, description="the paper's 200")
    robust_loss: RobustLoss = "cauchy"
    kernel_scale_initial_m: float = Field(
        default=0.1, gt=0, description="the robust kernel's scale at the first iteration"
    )
    kernel_scale_decay: float = Field(
        default=0.8, gt=0, le=1, description="the scale shrinks by this factor every iteration..."
    )
    kernel_scale_min_m: float = Field(default=0.015, gt=0, description="...down to this")
    max_normal_angle_deg: float | None = Field(
        default=45.0,
        gt=0,
        le=180,
        description="coarse phase: pairs whose surface normals (facing their sensors) differ more "
        "are dropped: the front and the back of an object seen from opposite sides are not the "
        "same surface, and far from the solution such pairs pull the wrong way",
    )
    fine_max_normal_angle_deg: float | None = Field(
        default=None,
        gt=0,
        le=180,
        description="the same gate in the final phase (None: no gate). Close to the solution the "
        "gate itself biases: it drops the pairs on one side of every edge and curved patch, and "
        "on a driven loop that turned the rear LiDAR's yaw by 0.1-0.25 deg",
    )
    max_correspondence_m: float = Field(
        default=0.5, gt=0, description="pairs further apart than this are ignored"
    )
    point_sigma_m: float = Field(
        default=0.01, gt=0, description="standard deviation of a point residual"
    )
    reference_self_consistency: bool = True
    lidar_self_consistency: bool = Field(
        default=False,
        description="every LiDAR's object map kept self-consistent across stops, not only the "
        "reference's: more constraints on the stop poses",
    )
    floor_terms: bool = True
    floor_normal_sigma_deg: float = Field(default=0.02, gt=0)
    floor_offset_sigma_m: float = Field(default=0.001, gt=0)
    self_neighbours: int = Field(
        default=4,
        ge=1,
        description="neighbours searched for a reference point's match from another stop",
    )
    normal_neighbours: int = Field(
        default=30, ge=3, description="neighbours of a reference point whose plane gives its normal"
    )
    smooth_clouds: bool = Field(
        default=True,
        description="project every object point onto its local plane (removes range noise)",
    )
    max_points_per_cloud: int | None = Field(
        default=1000,
        ge=10,
        description="random subset of each (LiDAR, stop) object cloud in the final phase; None "
        "keeps all (at full rate ~2.5k: about 1.5 mm better, three times slower)",
    )
    coarse_points_per_cloud: int | None = Field(
        default=300,
        ge=10,
        description="a first phase on this many points per cloud gets close cheaply; None: no "
        "coarse phase",
    )
    translation_tolerance_m: float = Field(
        default=1e-4, gt=0, description="converged when no pose moves more than this in one step"
    )
    rotation_tolerance_deg: float = Field(default=1e-3, gt=0)
    initial_damping: float = Field(
        default=1e-4, ge=0, description="Levenberg-Marquardt lambda at start"
    )
    seed: int = 0


@dataclass(frozen=True)
class ParameterLayout:
    """Where each pose's 6 parameters sit in the state vector; stop 0 and LiDAR 0 are fixed."""

    n_stops: int
    n_lidars: int

    @property
    def size(self) -> int:
        return 6 * (self.n_stops - 1 + self.n_lidars - 1)

    def stop(self, index: int) -> int:
        """First column of stop `index`, -1 when fixed."""
        return -1 if index == 0 else 6 * (index - 1)

    def lidar(self, index: int) -> int:
        """First column of LiDAR `index`, -1 when fixed."""
        return -1 if index == 0 else 6 * (self.n_stops - 1) + 6 * (index - 1)


@dataclass(frozen=True)
class OptimisationResult:
    """Refined `T_G_ref` (J, 4, 4) and `T_ref_lidar` (L, 4, 4), with how it got there.

    `error_per_iteration[k]`: eq. 11 before step k (mean nearest-neighbour distance, metres, of
    the non-reference object points to the reference map), the last entry after the final step.
    `T_ref_lidar_per_iteration` (K + 1, L, 4, 4): the extrinsics before each step and at the end.
    `information` (P, P): J^T W J at the solution, weights in 1/sigma^2 (see `layout`), and
    `gradient` (P,) J^T W r there; `stop_information` (J, P, P) and `stop_gradient` (J, P): the
    parts of both that come from the residuals touching each stop (its points as source or as
    target, its floor planes), for a leave-one-stop-out jackknife (`observability`);
    `variance_factor`: a-posteriori sum of weighted squared residuals over the redundancy.
    """

    T_G_ref: NDArray[np.float64]
    T_ref_lidar: NDArray[np.float64]
    converged: bool
    iterations: int
    error_per_iteration: tuple[float, ...]
    T_ref_lidar_per_iteration: NDArray[np.float64]
    information: NDArray[np.float64]
    gradient: NDArray[np.float64]
    stop_information: NDArray[np.float64]
    stop_gradient: NDArray[np.float64]
    variance_factor: float
    layout: ParameterLayout
    correspondences: tuple[int, ...]
    residual_rms_m: float
    seconds: float


# -- data kept across iterations ---------------------------------------------------------------


@dataclass(frozen=True)
class _Clouds:
    """Object clouds concatenated: rows of (lidar, stop) slices, points in their own frame."""

    points: Points
    lidar: NDArray[np.int64]
    stop: NDArray[np.int64]
    slices: tuple[tuple[int, int, int, int], ...]  # (lidar, stop, start, end)

    @staticmethod
    def build(parts: Sequence[tuple[int, int, Points]]) -> _Clouds:
        slices, start = [], 0
        for lidar, stop, pts in parts:
            slices.append((lidar, stop, start, start + len(pts)))
            start += len(pts)
        points = np.concatenate([p for *_, p in parts]) if parts else np.zeros((0, 3))
        sizes = [len(p) for *_, p in parts]
        lidar_of = np.repeat(np.array([i for i, *_ in parts], dtype=np.int64), sizes)
        stop_of = np.repeat(np.array([j for _, j, _ in parts], dtype=np.int64), sizes)
        return _Clouds(
            np.ascontiguousarray(points, dtype=np.float64), lidar_of, stop_of, tuple(slices)
        )

    def transformed(self, poses: Sequence[Matrix4], vectors: Points | None = None) -> Points:
        """Each slice's points (or `vectors`, rotated only) mapped by `poses[slice]` (4, 4)."""
        source = self.points if vectors is None else vectors
        out = np.empty_like(source)
        for (_, _, a, b), T in zip(self.slices, poses, strict=True):
            out[a:b] = source[a:b] @ T[:3, :3].T
            if vectors is None:
                out[a:b] += T[:3, 3]
        return out


def _cross(a: Points, b: Points) -> Points:
    """Row-wise cross product of (N, 3) arrays; `np.cross` spends more on axis bookkeeping."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def robust_weight_and_cost(
    distance: NDArray[np.float64], scale: float, loss: RobustLoss
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """IRLS weight w(s) = rho'(s)/s and cost rho(s) for distances `s` (N,); rho(s) ~ s^2/2 at 0."""
    if loss == "cauchy":
        ratio = (distance / scale) ** 2
        return 1.0 / (1.0 + ratio), 0.5 * scale**2 * np.log1p(ratio)
    if loss == "huber":
        inside = distance <= scale
        weight = np.where(inside, 1.0, scale / np.maximum(distance, 1e-300))
        cost = np.where(inside, 0.5 * distance**2, scale * (distance - 0.5 * scale))
        return weight, cost
    return np.ones_like(distance), 0.5 * distance**2


@dataclass(frozen=True)
class _Placed:
    """Every cloud placed with one set of poses: sources in the reference frame of their stop
    (`source_ref`) and in G, the target maps in the same two frames and their normals in G."""

    source_ref: Points
    source_G: Points
    source_normals_G: Points
    reference_ref: Points
    reference_G: Points
    normals_G: Points


@dataclass(frozen=True)
class _Pairs:
    """Associations of one iteration: source rows, target rows in the reference map."""

    source: NDArray[np.int64]
    target: NDArray[np.int64]
    cross_error: float  # eq. 11 over every non-reference point (no gate)


class _Problem:
    """Everything one iteration needs; poses are passed in so trial steps can be evaluated."""

    def __init__(
        self,
        objects: Sequence[Sequence[Points]],
        planes: Sequence[Sequence[Plane | None]] | None,
        floor_G: Plane | None,
        n_stops: int,
        config: OptimisationConfig,
        normals: Sequence[Sequence[Points]] | None = None,
    ) -> None:
        self.config = config
        self.layout = ParameterLayout(n_stops, len(objects))
        rng = np.random.default_rng(config.seed)
        parts: list[tuple[int, int, Points]] = []
        kept: list[tuple[int, int, NDArray[np.int64]]] = []
        for lidar, clouds in enumerate(objects):
            for stop, cloud in enumerate(clouds):
                pts = np.asarray(cloud, dtype=np.float64)
                keep = np.arange(len(pts))
                cap = config.max_points_per_cloud
                if cap is not None and len(pts) > cap:
                    keep = np.sort(rng.choice(len(pts), size=cap, replace=False))
                if len(keep):
                    parts.append((lidar, stop, pts[keep]))
                    kept.append((lidar, stop, keep))
        if normals is None:
            # Every cloud is smoothed the same way, as source and as target: an asymmetric
            # treatment (only the reference smoothed) measured a bias of 1-2 cm on range noise.
            surfaces = [local_planes(p, config.normal_neighbours) for *_, p in parts]
            if config.smooth_clouds:
                parts = [
                    (i, j, surface[0]) for (i, j, _), surface in zip(parts, surfaces, strict=True)
                ]
            part_normals = [surface[1] for surface in surfaces]
        else:
            part_normals = [
                np.asarray(normals[i][j], dtype=np.float64)[keep] for i, j, keep in kept
            ]
        # Normals face their sensor (at each cloud's origin), so that the two sides of a thin
        # object, seen by LiDARs on opposite sides, are told apart by their normals.
        part_normals = [
            orient_towards_origin(p, n) for (*_, p), n in zip(parts, part_normals, strict=True)
        ]
        # Targets: the reference LiDAR's map, and every LiDAR's own when it is kept consistent.
        is_target = [p[0] == 0 or config.lidar_self_consistency for p in parts]
        self.reference = _Clouds.build([p for p, t in zip(parts, is_target, strict=True) if t])
        reference_normals = [n for n, t in zip(part_normals, is_target, strict=True) if t]
        self.reference_normals = (
            np.concatenate(reference_normals) if reference_normals else np.zeros((0, 3))
        )
        used = [p[0] > 0 or config.reference_self_consistency for p in parts]
        self.sources = _Clouds.build([p for p, u in zip(parts, used, strict=True) if u])
        source_normals = [n for n, u in zip(part_normals, used, strict=True) if u]
        self.source_normals = np.concatenate(source_normals) if source_normals else np.zeros((0, 3))
        self.source_starts = np.array([a for *_, a, _ in self.sources.slices], dtype=np.int64)
        self.floor: list[tuple[int, int, Plane]] = []
        if planes is not None and floor_G is not None and config.floor_terms:
            self.floor = [
                (lidar, stop, plane)
                for lidar, row in enumerate(planes)
                for stop, plane in enumerate(row)
                if plane is not None
            ]
        self.floor_G = floor_G
        self.floor_sigma = np.array(
            [np.radians(config.floor_normal_sigma_deg)] * 2 + [config.floor_offset_sigma_m]
        )

    def place(self, T_G_ref: NDArray[np.float64], T_ref_lidar: NDArray[np.float64]) -> _Placed:
        sources, reference = self.sources.slices, self.reference.slices
        source_ref = self.sources.transformed([T_ref_lidar[i] for i, *_ in sources])
        source_G = _Clouds(source_ref, self.sources.lidar, self.sources.stop, sources).transformed(
            [T_G_ref[j] for _, j, *_ in sources]
        )
        source_poses = [T_G_ref[j] @ T_ref_lidar[i] for i, j, *_ in sources]
        reference_ref = self.reference.transformed([T_ref_lidar[i] for i, *_ in reference])
        reference_G = _Clouds(
            reference_ref, self.reference.lidar, self.reference.stop, reference
        ).transformed([T_G_ref[j] for _, j, *_ in reference])
        reference_poses = [T_G_ref[j] @ T_ref_lidar[i] for i, j, *_ in reference]
        return _Placed(
            source_ref,
            source_G,
            self.sources.transformed(source_poses, self.source_normals),
            reference_ref,
            reference_G,
            self.reference.transformed(reference_poses, self.reference_normals),
        )

    # -- association -------------------------------------------------------------------------

    def associate(self, placed: _Placed) -> _Pairs:
        empty = np.zeros(0, dtype=np.int64)
        if len(self.reference.points) == 0 or len(self.sources.points) == 0:
            return _Pairs(empty, empty, float("nan"))
        gate = self.config.max_correspondence_m
        sources, targets = [], []
        cross_error = float("nan")
        for lidar in range(self.layout.n_lidars):
            rows = np.flatnonzero(self.reference.lidar == lidar)
            if len(rows) == 0:
                continue
            tree = KDTree(placed.reference_G[rows])
            if lidar == 0:
                cross = np.flatnonzero(self.sources.lidar > 0)
                if len(cross):
                    distance, index = tree.query(placed.source_G[cross], k=1)
                    cross_error = float(np.mean(distance))
                    nearest = rows[index.astype(np.int64)]
                    keep = (distance < gate) & self._compatible(placed, cross, nearest)
                    sources.append(cross[keep])
                    targets.append(nearest[keep])
            own = np.flatnonzero(self.sources.lidar == lidar)
            if len(own) == 0:
                continue
            # The nearest point of the same LiDAR's map seen from *another* stop: a stop's own
            # points would tie every point to itself. Among the k nearest, the first from
            # another stop.
            k = min(self.config.self_neighbours, len(rows))
            distance, index = tree.query(placed.source_G[own], k=k, distance_upper_bound=gate)
            index = index.reshape(len(own), k)
            found = index < len(rows)
            candidates = rows[np.where(found, index, 0)]
            other = found & (self.reference.stop[candidates] != self.sources.stop[own][:, None])
            first = np.argmax(other, axis=1)
            nearest = candidates[np.arange(len(own)), first]
            keep = other[np.arange(len(own)), first]
            keep[keep] &= self._compatible(placed, own[keep], nearest[keep])
            sources.append(own[keep])
            targets.append(nearest[keep])
        return _Pairs(
            np.concatenate(sources) if sources else empty,
            np.concatenate(targets) if targets else empty,
            cross_error,
        )

    def _compatible(
        self, placed: _Placed, source: NDArray[np.int64], target: NDArray[np.int64]
    ) -> NDArray[np.bool_]:
        """Pairs whose surfaces face the same way (within `max_normal_angle_deg`)."""
        if self.config.max_normal_angle_deg is None:
            return np.ones(len(source), dtype=bool)
        cos = np.einsum("ni,ni->n", placed.source_normals_G[source], placed.normals_G[target])
        result: NDArray[np.bool_] = cos >= np.cos(np.radians(self.config.max_normal_angle_deg))
        return result

    # -- residuals ---------------------------------------------------------------------------

    def residuals(self, pairs: _Pairs, placed: _Placed) -> NDArray[np.float64]:
        """(n, 3) point-to-point or (n, 1) point-to-plane residuals, metres."""
        difference = placed.source_G[pairs.source] - placed.reference_G[pairs.target]
        if self.config.residual == "point_to_plane":
            normals = placed.normals_G[pairs.target]
            result: NDArray[np.float64] = np.einsum("ni,ni->n", normals, difference)[:, None]
            return result
        return difference

    def cost(
        self,
        pairs: _Pairs,
        T_G_ref: NDArray[np.float64],
        T_ref_lidar: NDArray[np.float64],
        scale: float,
    ) -> float:
        residual = self.residuals(pairs, self.place(T_G_ref, T_ref_lidar))
        _, cost = robust_weight_and_cost(
            np.linalg.norm(residual, axis=1), scale, self.config.robust_loss
        )
        floor_cost = 0.0
        if self.floor:
            floor_residual, _ = self._floor_terms(T_G_ref, T_ref_lidar, jacobians=False)
            floor_cost = 0.5 * float(np.sum(floor_residual**2))
        return float(np.sum(cost)) / self.config.point_sigma_m**2 + floor_cost

    def _floor_terms(
        self,
        T_G_ref: NDArray[np.float64],
        T_ref_lidar: NDArray[np.float64],
        *,
        jacobians: bool,
        ideal: bool = False,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Whitened floor residuals (K, 3) and, if asked, their Jacobians (K, 3, P).

        `ideal`: linearise at the common floor instead of at each observed plane. The exact
        Jacobian gives a turn about the floor normal a little leverage through each plane's
        residual tilt, which would make a bare floor look as if it fixed the yaw.
        """
        assert self.floor_G is not None
        normal_G, offset_G = self.floor_G.normal, self.floor_G.offset
        tangent = tangent_basis(normal_G)
        residual = np.empty((len(self.floor), 3))
        jac = np.zeros((len(self.floor), 3, self.layout.size if jacobians else 0))
        for row, (lidar, stop, plane) in enumerate(self.floor):
            normal, offset = plane_in_parent(plane, T_G_ref[stop] @ T_ref_lidar[lidar])
            residual[row, :2] = tangent.T @ (normal - normal_G)
            residual[row, 2] = offset - offset_G
            if not jacobians:
                continue
            at = normal_G if ideal else normal
            d_twist = np.zeros((3, 6))
            d_twist[:2, 3:] = -tangent.T @ hat(at)
            d_twist[2, :3] = -at
            if (col := self.layout.stop(stop)) >= 0:
                jac[row, :, col : col + 6] = d_twist
            if (col := self.layout.lidar(lidar)) < 0:
                continue
            if not ideal:
                jac[row, :, col : col + 6] = d_twist @ adjoint(T_G_ref[stop])
                continue
            # The same derivative with the plane taken as the floor itself in the reference
            # frame (the robot stands on the floor at every stop).
            R_stop, t_stop = T_G_ref[stop][:3, :3], T_G_ref[stop][:3, 3]
            floor_ref = T_G_ref[0][:3, :3].T @ normal_G
            jac[row, :2, col + 3 : col + 6] = -(tangent.T @ R_stop) @ hat(floor_ref)
            jac[row, 2, col : col + 3] = -floor_ref
            jac[row, 2, col + 3 : col + 6] = -_cross(floor_ref, R_stop.T @ t_stop)
        return residual / self.floor_sigma, jac / self.floor_sigma[None, :, None]

    # -- normal equations --------------------------------------------------------------------

    def normal_equations(
        self,
        pairs: _Pairs,
        T_G_ref: NDArray[np.float64],
        T_ref_lidar: NDArray[np.float64],
        scale: float,
        *,
        ideal_floor: bool = False,
        floor_stop: int | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], float, int]:
        """H = J^T W J, b = J^T W r (weights in 1/sigma^2), the weighted squared residual sum
        and the number of residual rows. `ideal_floor`: see `_floor_terms`; `floor_stop`: only
        that stop's floor terms (None: every stop's)."""
        layout = self.layout
        H = np.zeros((layout.size, layout.size))
        b = np.zeros(layout.size)
        placed = self.place(T_G_ref, T_ref_lidar)
        # Rows grouped by (source cloud, target stop, target LiDAR): within a group the four
        # poses involved are the same, so one small GEMM gives the group's contribution.
        slice_of = np.searchsorted(self.source_starts, pairs.source, side="right") - 1
        target_stop = self.reference.stop[pairs.target]
        target_lidar = self.reference.lidar[pairs.target]
        key = (slice_of * layout.n_stops + target_stop) * layout.n_lidars + target_lidar
        order = np.argsort(key, kind="stable")
        src, tgt, key = pairs.source[order], pairs.target[order], key[order]
        sorted_pairs = _Pairs(src, tgt, pairs.cross_error)
        residual = self.residuals(sorted_pairs, placed)
        weight, _ = robust_weight_and_cost(
            np.linalg.norm(residual, axis=1), scale, self.config.robust_loss
        )
        weight = weight / self.config.point_sigma_m**2
        g, q, m = placed.source_G[src], placed.source_ref[src], placed.reference_G[tgt]
        q_target = placed.reference_ref[tgt]
        R_stop = T_G_ref[self.sources.stop[src]][:, :3, :3]
        R_target = T_G_ref[self.reference.stop[tgt]][:, :3, :3]
        n, rows = residual.shape
        jac = np.empty((n, rows, 24))
        if self.config.residual == "point_to_plane":
            n_G = placed.normals_G[tgt]
            n_ref = np.einsum("nji,nj->ni", R_stop, n_G)  # the normal in the reference frame
            jac[:, 0, 0:3] = n_G
            jac[:, 0, 3:6] = _cross(g, n_G)
            jac[:, 0, 6:9] = n_ref
            jac[:, 0, 9:12] = _cross(q, n_ref)
            jac[:, 0, 12:15] = -n_G
            # The target's normal turns with its stop too: d(n.(g - m))/d(phi_k).
            jac[:, 0, 15:18] = -_cross(m, n_G) + _cross(n_G, g - m)
            # ...and with its LiDAR's extrinsics (in the reference frame of its stop).
            u = np.einsum("nji,nj->ni", R_target, n_G)
            w = np.einsum("nji,nj->ni", R_target, g - m)
            jac[:, 0, 18:21] = -u
            jac[:, 0, 21:24] = _cross(u, q_target + w)
        else:
            eye = np.broadcast_to(np.eye(3), (n, 3, 3))
            jac[:, :, 0:3] = eye
            jac[:, :, 3:6] = -hat(g)
            jac[:, :, 6:9] = R_stop
            jac[:, :, 9:12] = -R_stop @ hat(q)
            jac[:, :, 12:15] = -eye
            jac[:, :, 15:18] = hat(m)
            jac[:, :, 18:21] = -R_target
            jac[:, :, 21:24] = R_target @ hat(q_target)
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if n else np.zeros(0, np.int64)
        ends = np.r_[starts[1:], n] if n else starts
        for a, b_end in zip(starts, ends, strict=True):
            group = int(key[a])
            t = group % layout.n_lidars
            k = (group // layout.n_lidars) % layout.n_stops
            lidar, j, *_ = self.sources.slices[group // layout.n_lidars // layout.n_stops]
            # Slots (S_j, C_i, S_k, C_t); a pose in two slots (the same stop, or a LiDAR's own
            # map) gets the sum of their blocks, a fixed pose none.
            slots: dict[int, list[int]] = {}
            for slot, column in enumerate(
                (layout.stop(j), layout.lidar(lidar), layout.stop(k), layout.lidar(t))
            ):
                if column >= 0:
                    slots.setdefault(column, []).append(slot)
            if not slots:
                continue
            block = np.concatenate(
                [
                    sum(jac[a:b_end, :, 6 * x : 6 * x + 6] for x in group_slots)
                    for group_slots in slots.values()
                ],
                axis=2,
            )
            wblock = block * weight[a:b_end, None, None]
            cols = np.concatenate([np.arange(c, c + 6) for c in slots])
            flat = block.reshape(-1, block.shape[2])
            wflat = wblock.reshape(-1, block.shape[2])
            H[np.ix_(cols, cols)] += wflat.T @ flat
            b[cols] += wflat.T @ residual[a:b_end].reshape(-1)
        chi2 = float(np.sum(weight[:, None] * residual**2))
        count = residual.size
        if self.floor:
            floor_residual, floor_jac = self._floor_terms(
                T_G_ref, T_ref_lidar, jacobians=True, ideal=ideal_floor
            )
            if floor_stop is not None:
                rows = np.array([stop == floor_stop for _, stop, _ in self.floor])
                floor_residual, floor_jac = floor_residual[rows], floor_jac[rows]
            H += np.einsum("kri,krj->ij", floor_jac, floor_jac)
            b += np.einsum("kri,kr->i", floor_jac, floor_residual)
            chi2 += float(np.sum(floor_residual**2))
            count += floor_residual.size
        return H, b, chi2, count


def _apply_step(
    step: NDArray[np.float64],
    layout: ParameterLayout,
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    new_stops, new_lidars = T_G_ref.copy(), T_ref_lidar.copy()
    for j in range(1, layout.n_stops):
        c = layout.stop(j)
        new_stops[j] = exp_se3(step[c : c + 6]) @ T_G_ref[j]
    for i in range(1, layout.n_lidars):
        c = layout.lidar(i)
        new_lidars[i] = exp_se3(step[c : c + 6]) @ T_ref_lidar[i]
    return new_stops, new_lidars


def _largest_motion(before: NDArray[np.float64], after: NDArray[np.float64]) -> tuple[float, float]:
    """Largest translation (m) and rotation (deg) between matching poses of two (N, 4, 4) stacks."""
    delta = np.linalg.inv(before) @ after
    translation = float(np.max(np.linalg.norm(after[:, :3, 3] - before[:, :3, 3], axis=1)))
    cos = np.clip((np.trace(delta[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)
    return translation, float(np.degrees(np.max(np.arccos(cos))))


def optimise(
    objects: Sequence[Sequence[Points]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    config: OptimisationConfig,
    *,
    planes: Sequence[Sequence[Plane | None]] | None = None,
    floor_G: Plane | None = None,
    normals: Sequence[Sequence[Points]] | None = None,
    on_iteration: Callable[[int], None] | None = None,
) -> OptimisationResult:
    """Refine the poses so every LiDAR's object map agrees with the reference LiDAR's.

    `objects[lidar][stop]`: (N, 3) object points in that LiDAR's frame; LiDAR 0 is the reference.
    `T_G_ref` (J, 4, 4): the reference's pose per stop (stop 0 fixed). `T_ref_lidar` (L, 4, 4):
    extrinsics relative to the reference (index 0 is the identity, fixed). `planes[lidar][stop]`
    and `floor_G` (stage 3) add the floor terms; without them only the objects count.
    `normals[lidar][stop]` (N, 3): the points' surface normals when the caller has them
    (segmentation does); without them they are fitted here, and the clouds smoothed if
    `smooth_clouds`. `on_iteration(k)` is called after iteration k (progress for a caller).
    """
    started = time.perf_counter()
    fine_config = config.model_copy(
        update={"max_normal_angle_deg": config.fine_max_normal_angle_deg}
    )
    fine = _Problem(objects, planes, floor_G, len(T_G_ref), fine_config, normals)
    layout = fine.layout
    phases = [fine]
    coarse_cap = config.coarse_points_per_cloud
    if coarse_cap is not None and (
        config.max_points_per_cloud is None or coarse_cap < config.max_points_per_cloud
    ):
        coarse_config = config.model_copy(update={"max_points_per_cloud": coarse_cap})
        phases.insert(0, _Problem(objects, planes, floor_G, len(T_G_ref), coarse_config, normals))
    stops = np.array(T_G_ref, dtype=np.float64)
    lidars = np.array(T_ref_lidar, dtype=np.float64)
    history = [lidars.copy()]
    errors: list[float] = []
    damping = config.initial_damping
    converged, iteration = False, 0
    scale = config.kernel_scale_min_m
    for phase, problem in enumerate(phases):
        last = phase == len(phases) - 1
        # The coarse phase only has to get close: it stops at ten times the tolerance.
        tolerance = 1.0 if last else 10.0
        converged = False
        pairs = problem.associate(problem.place(stops, lidars))
        while iteration < config.max_iterations:
            iteration += 1
            errors.append(pairs.cross_error)
            # Graduated robustness: wide at first, while everything is far off, then tight so
            # that parts one LiDAR saw and the reference did not stop pulling.
            scale = max(
                config.kernel_scale_min_m,
                config.kernel_scale_initial_m * config.kernel_scale_decay ** (iteration - 1),
            )
            stops, lidars, moved, damping = _step(problem, pairs, stops, lidars, scale, damping)
            history.append(lidars.copy())
            pairs = problem.associate(problem.place(stops, lidars))
            if on_iteration is not None:
                on_iteration(iteration)
            if moved is None or (
                moved[0] < tolerance * config.translation_tolerance_m
                and moved[1] < tolerance * config.rotation_tolerance_deg
                and (not last or scale <= config.kernel_scale_min_m)
            ):
                converged = True
                break
    problem = fine
    pairs = problem.associate(problem.place(stops, lidars))
    errors.append(pairs.cross_error)
    # The information matrix and the variance factor at the solution, with its associations.
    H = np.zeros((layout.size, layout.size))
    gradient = np.zeros(layout.size)
    chi2, count = 0.0, 0
    if len(pairs.source) or problem.floor:
        H, gradient, chi2, count = problem.normal_equations(
            pairs, stops, lidars, scale, ideal_floor=True
        )
    stop_H, stop_b = _stop_contributions(problem, pairs, stops, lidars, scale)
    redundancy = max(count - layout.size, 1)
    residual_rms = float("nan")
    if len(pairs.source):
        residual = problem.residuals(pairs, problem.place(stops, lidars))
        residual_rms = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
    per_lidar = np.bincount(problem.sources.lidar[pairs.source], minlength=layout.n_lidars)
    return OptimisationResult(
        T_G_ref=stops,
        T_ref_lidar=lidars,
        converged=converged,
        iterations=iteration,
        error_per_iteration=tuple(errors),
        T_ref_lidar_per_iteration=np.stack(history),
        information=H,
        gradient=gradient,
        stop_information=stop_H,
        stop_gradient=stop_b,
        variance_factor=chi2 / redundancy,
        layout=layout,
        correspondences=tuple(int(c) for c in per_lidar),
        residual_rms_m=residual_rms,
        seconds=time.perf_counter() - started,
    )


def _stop_contributions(
    problem: _Problem,
    pairs: _Pairs,
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
    scale: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per stop, the information (J, P, P) and gradient (J, P) of the residuals that touch it.

    A pair touches stop j when its source or its target point was seen there; a pair between two
    stops counts for both, as leaving either out removes it.
    """
    layout = problem.layout
    H = np.zeros((layout.n_stops, layout.size, layout.size))
    b = np.zeros((layout.n_stops, layout.size))
    source_stop = problem.sources.stop[pairs.source]
    target_stop = problem.reference.stop[pairs.target]
    for j in range(layout.n_stops):
        touching = (source_stop == j) | (target_stop == j)
        if not touching.any() and not any(stop == j for _, stop, _ in problem.floor):
            continue
        subset = _Pairs(pairs.source[touching], pairs.target[touching], pairs.cross_error)
        H[j], b[j], _, _ = problem.normal_equations(
            subset, stops, lidars, scale, ideal_floor=True, floor_stop=j
        )
    return H, b


def _step(
    problem: _Problem,
    pairs: _Pairs,
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
    scale: float,
    damping: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[float, float] | None, float]:
    """One Levenberg-Marquardt step with fixed associations: the new poses, the largest motion
    (m, deg) of any pose (None when no step lowered the cost) and the new damping."""
    layout = problem.layout
    H, b, _, _ = problem.normal_equations(pairs, stops, lidars, scale)
    cost = problem.cost(pairs, stops, lidars, scale)
    # A pose nothing constrains (no objects, no floor) keeps its value instead of a singular
    # solve; the observability stage reports it.
    floor = 1e-12 * max(float(np.trace(H)) / max(layout.size, 1), 1.0)
    for _ in range(10):
        A = H + damping * np.diag(np.diag(H)) + floor * np.eye(layout.size)
        step = np.asarray(-np.linalg.solve(A, b), dtype=np.float64)
        trial_stops, trial_lidars = _apply_step(step, layout, stops, lidars)
        if problem.cost(pairs, trial_stops, trial_lidars, scale) <= cost:
            stop_motion = _largest_motion(stops, trial_stops)
            lidar_motion = _largest_motion(lidars, trial_lidars)
            moved = (max(stop_motion[0], lidar_motion[0]), max(stop_motion[1], lidar_motion[1]))
            return trial_stops, trial_lidars, moved, max(damping / 3.0, 1e-9)
        damping = max(damping * 4.0, 1e-6)
    return stops, lidars, None, damping
