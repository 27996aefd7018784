"""Stage 3: roll, pitch and height of every stop and every LiDAR from the floor planes they see.

Least squares over all stops and LiDARs at once (the paper aligns to the first stop only): one
floor plane in the global frame G, and for every observed plane the tilt and offset between it,
mapped into G through `T_G_ref(stop) @ T_ref_lidar`, and that floor. Only the three degrees of
freedom the floor constrains move (tilt about the pose's own origin, shift along the normal);
x, y and yaw stay as they came, for the objects of stage 4 to fix.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from pipeline.errors import BadInputError
from pipeline.geometry import Plane, adjoint, exp_se3, hat, plane_in_parent, tangent_basis

_FROZEN = ConfigDict(frozen=True, extra="forbid")


class RoughRefinementConfig(BaseModel):
    """Gauss-Newton on plane residuals; sigmas weigh tilt against offset, the Cauchy kernel (in
    sigmas) discounts a wrong plane (a box top taken for the floor)."""

    model_config = _FROZEN

    enabled: bool = True
    max_iterations: int = Field(default=20, ge=1)
    normal_sigma_deg: float = Field(default=0.1, gt=0)
    offset_sigma_m: float = Field(default=0.002, gt=0)
    cauchy_scale: float = Field(default=5.0, gt=0, description="robust kernel scale, in sigmas")
    step_tolerance: float = Field(
        default=1e-10, gt=0, description="stop when the step's norm is below"
    )


@dataclass(frozen=True)
class PlaneResiduals:
    """RMS over the used plane observations: tilt (deg) and offset (m) against the common floor."""

    tilt_deg: float
    offset_m: float


@dataclass(frozen=True)
class RoughRefinementResult:
    """Refined poses; `floor_G` is the floor in G. Shapes: `T_G_ref` (J, 4, 4), `T_ref_lidar`
    (L, 4, 4) with the reference first (identity)."""

    T_G_ref: NDArray[np.float64]
    T_ref_lidar: NDArray[np.float64]
    floor_G: Plane
    converged: bool
    iterations: int
    residual_initial: PlaneResiduals
    residual_final: PlaneResiduals
    observations: int
    seconds: float


def floor_dof_basis(
    normal: NDArray[np.float64], origin: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(6, 3) twist basis `[rho; phi]` of the three motions the floor sees: tilts about two axes
    orthogonal to `normal` through `origin`, and a shift along `normal`."""
    tangent = tangent_basis(normal)
    basis = np.zeros((6, 3))
    basis[3:, :2] = tangent
    # A rotation phi about `origin` is the twist [origin x phi; phi].
    basis[:3, :2] = np.cross(origin, tangent.T).T
    basis[:3, 2] = normal
    return basis


def _residuals(
    observations: Sequence[tuple[int, int, Plane]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    normal_G: NDArray[np.float64],
    offset_G: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Tilt (K, 2) in the floor's tangent basis (rad), offset (K,) (m), mapped normals (K, 3)."""
    tangent = tangent_basis(normal_G)
    normals = np.empty((len(observations), 3))
    offsets = np.empty(len(observations))
    for row, (lidar, stop, plane) in enumerate(observations):
        normals[row], offsets[row] = plane_in_parent(plane, T_G_ref[stop] @ T_ref_lidar[lidar])
    return (normals - normal_G) @ tangent, offsets - offset_G, normals


def refine_with_floor(
    planes: Sequence[Sequence[Plane | None]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    config: RoughRefinementConfig,
) -> RoughRefinementResult:
    """Align every (LiDAR, stop) floor plane to one floor in G.

    `planes[lidar][stop]`: the floor seen by that LiDAR at that stop in its own frame, or None.
    `T_G_ref` (J, 4, 4): the reference LiDAR's pose per stop; stop 0 is held fixed (the gauge).
    `T_ref_lidar` (L, 4, 4): extrinsics relative to the reference, which is index 0 (held fixed).
    Raises `BadInputError` when no LiDAR saw the floor anywhere.
    """
    started = time.perf_counter()
    T_G_ref = np.array(T_G_ref, dtype=np.float64)
    T_ref_lidar = np.array(T_ref_lidar, dtype=np.float64)
    n_lidars, n_stops = len(T_ref_lidar), len(T_G_ref)
    observations = [
        (lidar, stop, plane)
        for lidar in range(n_lidars)
        for stop in range(n_stops)
        if (plane := planes[lidar][stop]) is not None
    ]
    if not observations:
        raise BadInputError(
            "no LiDAR saw a floor plane at any stop; the method needs the floor "
            "(check the recording, or the segmentation's floor_distance_m and max_floor_tilt_deg)"
        )
    # Seed the floor with the reference's own view when it has one (G is tied to it).
    first = next((o for o in observations if o[0] == 0), observations[0])
    normal_G, offset_G = plane_in_parent(first[2], T_G_ref[first[1]] @ T_ref_lidar[first[0]])

    sigma = np.array([np.radians(config.normal_sigma_deg)] * 2 + [config.offset_sigma_m])
    n_params = 3 + 3 * (n_stops - 1) + 3 * (n_lidars - 1)

    def summary(tilt: NDArray[np.float64], offset: NDArray[np.float64]) -> PlaneResiduals:
        return PlaneResiduals(
            tilt_deg=float(np.degrees(np.sqrt(np.mean(np.sum(tilt**2, axis=1))))),
            offset_m=float(np.sqrt(np.mean(offset**2))),
        )

    tilt, offset, _ = _residuals(observations, T_G_ref, T_ref_lidar, normal_G, offset_G)
    initial = summary(tilt, offset)
    converged, iterations = False, 0
    for iterations in range(1, config.max_iterations + 1):  # noqa: B007 (reported below)
        tilt, offset, normals = _residuals(observations, T_G_ref, T_ref_lidar, normal_G, offset_G)
        residual = np.column_stack([tilt, offset]) / sigma
        weight = 1.0 / (1.0 + np.sum(residual**2, axis=1) / config.cauchy_scale**2)
        tangent = tangent_basis(normal_G)
        # The floor's normal in the reference frame: the same at every stop, the robot stays on it.
        normal_ref = T_G_ref[0][:3, :3].T @ normal_G
        jac = np.zeros((len(observations), 3, n_params))
        jac[:, 0, 0] = jac[:, 1, 1] = -1.0
        jac[:, 2, 2] = -1.0
        for row, (lidar, stop, _) in enumerate(observations):
            # d(residual)/d(left twist in G) of the pose mapping this plane into G.
            d_twist = np.zeros((3, 6))
            d_twist[:2, 3:] = -tangent.T @ hat(normals[row])
            d_twist[2, :3] = -normals[row]
            if stop > 0:
                basis = floor_dof_basis(normal_G, T_G_ref[stop][:3, 3])
                col = 3 + 3 * (stop - 1)
                jac[row, :, col : col + 3] = d_twist @ basis
            if lidar > 0:
                basis = floor_dof_basis(normal_ref, T_ref_lidar[lidar][:3, 3])
                col = 3 + 3 * (n_stops - 1) + 3 * (lidar - 1)
                jac[row, :, col : col + 3] = d_twist @ adjoint(T_G_ref[stop]) @ basis
        jac /= sigma[None, :, None]
        weighted = jac * weight[:, None, None]
        hessian = np.einsum("kri,krj->ij", weighted, jac)
        gradient = np.einsum("kri,kr->i", weighted, residual)
        # Tiny damping: a stop or LiDAR without any plane keeps its pose (no singular solve).
        hessian[np.diag_indices(n_params)] += 1e-9 * max(float(hessian.diagonal().max()), 1.0)
        step = -np.linalg.solve(hessian, gradient)
        # Poses move along the bases the Jacobian was built with (the floor before this step).
        for stop in range(1, n_stops):
            col = 3 + 3 * (stop - 1)
            basis = floor_dof_basis(normal_G, T_G_ref[stop][:3, 3])
            T_G_ref[stop] = exp_se3(basis @ step[col : col + 3]) @ T_G_ref[stop]
        for lidar in range(1, n_lidars):
            col = 3 + 3 * (n_stops - 1) + 3 * (lidar - 1)
            basis = floor_dof_basis(normal_ref, T_ref_lidar[lidar][:3, 3])
            T_ref_lidar[lidar] = exp_se3(basis @ step[col : col + 3]) @ T_ref_lidar[lidar]
        normal_G = normal_G + tangent @ step[:2]
        normal_G /= np.linalg.norm(normal_G)
        offset_G += float(step[2])
        if float(np.linalg.norm(step)) < config.step_tolerance:
            converged = True
            break
    tilt, offset, _ = _residuals(observations, T_G_ref, T_ref_lidar, normal_G, offset_G)
    return RoughRefinementResult(
        T_G_ref=T_G_ref,
        T_ref_lidar=T_ref_lidar,
        floor_G=Plane(normal=normal_G, offset=offset_G),
        converged=converged,
        iterations=iterations,
        residual_initial=initial,
        residual_final=summary(tilt, offset),
        observations=len(observations),
        seconds=time.perf_counter() - started,
    )
