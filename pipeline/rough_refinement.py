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
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from pipeline.errors import BadInputError
from pipeline.geometry import Plane, adjoint, exp_se3, hat, plane_in_parent, tangent_basis
from pipeline.transforms import Points

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
    """Floor residuals against the common floor: tilt (deg) and offset (m). As `residual_*` the
    RMS over the used plane observations; as `noise` one observation's robust spread per tilt
    axis and for the offset (`floor_noise`)."""

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
    noise: PlaneResiduals | None = None
    """The spread of one floor observation about the common floor after the fit (`floor_noise`);
    None where the fit leaves no redundancy to measure it."""


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


class PlaneObservation(NamedTuple):
    """A floor plane one LiDAR saw at one stop, in that LiDAR's frame."""

    lidar: int
    stop: int
    plane: Plane


def plane_observations(planes: Sequence[Sequence[Plane | None]]) -> list[PlaneObservation]:
    """Every plane of `planes[lidar][stop]` that is not None, LiDAR by LiDAR, stop by stop."""
    return [
        PlaneObservation(lidar, stop, plane)
        for lidar, row in enumerate(planes)
        for stop, plane in enumerate(row)
        if plane is not None
    ]


def _residuals(
    observations: Sequence[PlaneObservation],
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


def _summary(tilt: NDArray[np.float64], offset: NDArray[np.float64]) -> PlaneResiduals:
    return PlaneResiduals(
        tilt_deg=float(np.degrees(np.sqrt(np.mean(np.sum(tilt**2, axis=1))))),
        offset_m=float(np.sqrt(np.mean(offset**2))),
    )


# Parameters: the floor's tilt (2) and offset (1), then 3 per stop and 3 per LiDAR past the first.


def _stop_column(stop: int) -> int:
    return 3 + 3 * (stop - 1)


def _lidar_column(lidar: int, n_stops: int) -> int:
    return 3 + 3 * (n_stops - 1) + 3 * (lidar - 1)


def _parameter_count(n_stops: int, n_lidars: int) -> int:
    return 3 + 3 * (n_stops - 1) + 3 * (n_lidars - 1)


def _floor_in_reference(T_G_ref: NDArray[np.float64], normal_G: NDArray[np.float64]) -> Points:
    """The floor's normal in the reference frame: the same at every stop, the robot stays on it."""
    normal_ref: Points = T_G_ref[0][:3, :3].T @ normal_G
    return normal_ref


def _jacobian(
    observations: Sequence[PlaneObservation],
    normals: NDArray[np.float64],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    normal_G: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(K, 3, P) derivatives of the tilt (2) and offset (1) residuals of every observation, whose
    planes mapped into G have the `normals` (K, 3)."""
    n_stops, n_lidars = len(T_G_ref), len(T_ref_lidar)
    tangent = tangent_basis(normal_G)
    normal_ref = _floor_in_reference(T_G_ref, normal_G)
    jac = np.zeros((len(observations), 3, _parameter_count(n_stops, n_lidars)))
    jac[:, 0, 0] = jac[:, 1, 1] = -1.0
    jac[:, 2, 2] = -1.0
    for row, (lidar, stop, _) in enumerate(observations):
        # d(residual)/d(left twist in G) of the pose mapping this plane into G.
        d_twist = np.zeros((3, 6))
        d_twist[:2, 3:] = -tangent.T @ hat(normals[row])
        d_twist[2, :3] = -normals[row]
        if stop > 0:
            basis = floor_dof_basis(normal_G, T_G_ref[stop][:3, 3])
            col = _stop_column(stop)
            jac[row, :, col : col + 3] = d_twist @ basis
        if lidar > 0:
            basis = floor_dof_basis(normal_ref, T_ref_lidar[lidar][:3, 3])
            col = _lidar_column(lidar, n_stops)
            jac[row, :, col : col + 3] = d_twist @ adjoint(T_G_ref[stop]) @ basis
    return jac


def _gauss_newton_step(
    observations: Sequence[PlaneObservation],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    floor_G: tuple[NDArray[np.float64], float],
    config: RoughRefinementConfig,
) -> NDArray[np.float64]:
    """The step (P,) of one reweighted Gauss-Newton iteration from these poses and floor."""
    sigma = np.array([np.radians(config.normal_sigma_deg)] * 2 + [config.offset_sigma_m])
    tilt, offset, normals = _residuals(observations, T_G_ref, T_ref_lidar, *floor_G)
    residual = np.column_stack([tilt, offset]) / sigma
    weight = 1.0 / (1.0 + np.sum(residual**2, axis=1) / config.cauchy_scale**2)
    jac = _jacobian(observations, normals, T_G_ref, T_ref_lidar, floor_G[0])
    jac /= sigma[None, :, None]
    weighted = jac * weight[:, None, None]
    hessian = np.einsum("kri,krj->ij", weighted, jac)
    gradient = np.einsum("kri,kr->i", weighted, residual)
    # Tiny damping: a stop or LiDAR without any plane keeps its pose (no singular solve).
    hessian[np.diag_indices(len(hessian))] += 1e-9 * max(float(hessian.diagonal().max()), 1.0)
    step: NDArray[np.float64] = -np.linalg.solve(hessian, gradient)
    return step


def _move(
    step: NDArray[np.float64],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    floor_G: tuple[NDArray[np.float64], float],
) -> tuple[NDArray[np.float64], float]:
    """Apply `step` to the poses (in place) and return the moved floor (normal, offset) in G.

    Poses move along the bases the Jacobian was built with (the floor before this step).
    """
    normal_G, offset_G = floor_G
    normal_ref = _floor_in_reference(T_G_ref, normal_G)
    for stop in range(1, len(T_G_ref)):
        col = _stop_column(stop)
        basis = floor_dof_basis(normal_G, T_G_ref[stop][:3, 3])
        T_G_ref[stop] = exp_se3(basis @ step[col : col + 3]) @ T_G_ref[stop]
    for lidar in range(1, len(T_ref_lidar)):
        col = _lidar_column(lidar, len(T_G_ref))
        basis = floor_dof_basis(normal_ref, T_ref_lidar[lidar][:3, 3])
        T_ref_lidar[lidar] = exp_se3(basis @ step[col : col + 3]) @ T_ref_lidar[lidar]
    normal_G = normal_G + tangent_basis(normal_G) @ step[:2]
    normal_G /= np.linalg.norm(normal_G)
    return normal_G, offset_G + float(step[2])


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
    observations = plane_observations(planes)
    if not observations:
        raise BadInputError(
            "no LiDAR saw a floor plane at any stop; the method needs the floor "
            "(check the recording, or the segmentation's floor_distance_m and max_floor_tilt_deg)"
        )
    # Seed the floor with the reference's own view when it has one (G is tied to it).
    first = next((o for o in observations if o.lidar == 0), observations[0])
    floor_G = plane_in_parent(first.plane, T_G_ref[first.stop] @ T_ref_lidar[first.lidar])
    tilt, offset, _ = _residuals(observations, T_G_ref, T_ref_lidar, *floor_G)
    initial = _summary(tilt, offset)
    converged, iterations = False, 0
    for iterations in range(1, config.max_iterations + 1):  # noqa: B007 (reported below)
        step = _gauss_newton_step(observations, T_G_ref, T_ref_lidar, floor_G, config)
        floor_G = _move(step, T_G_ref, T_ref_lidar, floor_G)
        if float(np.linalg.norm(step)) < config.step_tolerance:
            converged = True
            break
    tilt, offset, _ = _residuals(observations, T_G_ref, T_ref_lidar, *floor_G)
    return RoughRefinementResult(
        T_G_ref=T_G_ref,
        T_ref_lidar=T_ref_lidar,
        floor_G=Plane(normal=floor_G[0], offset=floor_G[1]),
        converged=converged,
        iterations=iterations,
        residual_initial=initial,
        residual_final=_summary(tilt, offset),
        observations=len(observations),
        seconds=time.perf_counter() - started,
        noise=floor_noise(tilt, offset, _parameter_count(len(T_G_ref), len(T_ref_lidar))),
    )


def floor_noise(
    tilt: NDArray[np.float64], offset: NDArray[np.float64], parameters: int
) -> PlaneResiduals | None:
    """How far one LiDAR's floor at one stop lies from the common floor once the poses are fitted:
    per tilt component and for the offset, a robust standard deviation of the residuals `tilt`
    (K, 2, rad) and `offset` (K,, m) (1.4826 times their median absolute value: a box top taken
    for the floor does not count), scaled by sqrt(rows / (rows - parameters)) for what the fit
    absorbed. It holds what makes two LiDARs' floors disagree at one stop: plane-fit noise, and
    on a real floor its waves and joints under each LiDAR's view. None when the rows do not
    exceed the parameters or the residuals do not spread at all (noiseless planes)."""
    rows = 3 * len(offset)
    if rows <= parameters:
        return None
    inflation = float(np.sqrt(rows / (rows - parameters)))
    tilt_rad = 1.4826 * float(np.median(np.abs(tilt))) * inflation
    offset_m = 1.4826 * float(np.median(np.abs(offset))) * inflation
    if tilt_rad <= 0.0 or offset_m <= 0.0:
        return None
    return PlaneResiduals(tilt_deg=float(np.degrees(tilt_rad)), offset_m=offset_m)
