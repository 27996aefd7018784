"""How well the data fix each LiDAR's pose: 1-sigma per degree of freedom from the final Hessian,
and the degrees of freedom the data cannot determine at all.

Axes: x, y, z and roll, pitch, yaw are about the *level base frame* (the base frame turned so its
z axis is the measured floor normal), through the LiDAR's own origin. The floor alone fixes
z, roll and pitch in exactly these axes, so x, y and yaw of a LiDAR without objects show up here
by name instead of smeared over all six. The reference LiDAR is the datum: its stddev are zero.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from pipeline.geometry import adjoint, hat, log_se3
from pipeline.optimisation import OptimisationResult, ParameterLayout
from pipeline.segmentation import SurfaceModel
from pipeline.transforms import Matrix4, make_transform

DOF_NAMES: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")


class ObservabilityConfig(BaseModel):
    """A weak prior (what "we know nothing" means) makes the covariance finite; a DoF whose
    formal posterior stddev stays above `undetermined_fraction` of the prior was not fixed by the
    data.

    The formal covariance treats every residual as independent. They are not: neighbouring object
    points share their local surface fit and its small bias, which the optimiser cannot average
    away, so the true error is several times the formal 1-sigma. The reported 1-sigma is therefore
    measured on the recording itself: a leave-one-stop-out jackknife and a leave-one-block-out
    one over blocks of space (`jackknife`), the spread of the solutions the data give without
    each stop or each patch of surfaces in turn, never smaller than the formal one. A misfit
    that every stop and every patch repeat moves no jackknife: the one the data can measure, a
    range bias per LiDAR, is estimated and its effect added (`range_bias`).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    prior_translation_m: float = Field(default=1.0, gt=0)
    prior_rotation_deg: float = Field(default=30.0, gt=0)
    undetermined_fraction: float = Field(default=0.5, gt=0, lt=1)
    range_bias: Literal["estimated", "none"] = Field(
        default="none",
        description="estimated: each LiDAR's range bias is estimated from the recording (the "
        "poses and one bias per LiDAR solved together) and what a bias that large does to the "
        "poses is added to the reported covariance: a misfit every stop and every surface "
        "repeats, which no jackknife can see. Opt-in: on bench_random seeds 1000-1005 and 1013 "
        "(rate 0.3) it takes the RMS of error/sigma from 5.4 to 1.6 with no false fail and "
        "fails the biased ones (seed 1013 at full rate, 11 mm off: 1.3 -> 6.0 mm), but on the "
        "paper's arcs with front/rear rosettes (set1-box, set2-box, set1-cylinder) a common "
        "bias of all LiDARs is barely told from the baseline: it reports 31-40 mm there and "
        "fails runs 1.8-3.5 mm off; none: left out",
    )
    surface_sensitivity_passes: int | None = Field(
        default=None,
        ge=2,
        description="N: stage 4 is run again from its solution on object points projected N "
        "times onto their local surfaces (`segmentation.surface_passes`) instead of "
        "segmentation's once, and how far each pose moves, less what chance alone would move "
        "it (a jackknife over stops of the linearised shift), is added to its reported "
        "covariance as a systematic error: the smoothed surfaces' offset under range noise, "
        "which every stop and every patch repeat and so no jackknife sees, is what the extra "
        "passes change (`pipeline.stages.sensitivity`). Opt-in: it fails bench_random seed "
        "1060 (10.1 mm off, passed by the default with a 1-sigma of 0.3 mm; now 5.5 mm) but "
        "doubles the seconds per recording, and on sparse clouds (set 1 at 5-10 % of the "
        "point rate) the extra passes bend the surfaces themselves and fail good calibrations "
        "(1.6 mm off, 5.3-5.5 mm reported), see docs/method.md; all measured with the quadric "
        "surfaces (`segmentation.surface_model: quadric`), before the beam quadric became the "
        "default. None: left out",
    )
    surface_sensitivity_model: SurfaceModel | Literal["alternative"] | None = Field(
        default="alternative",
        description="a surface model (`segmentation.surface_model`): stage 4 is run again from "
        "its solution on object points projected onto that model's surfaces instead, and how "
        "far each pose moves beyond chance is added to its reported covariance, as with "
        "surface_sensitivity_passes (both set: both changes at once): the calibration's "
        "dependence on how the surfaces are modelled, a misfit every stop and every patch "
        "repeat, which no jackknife sees. alternative (the default): the quadric where the "
        "calibration fits its surfaces along the beams (beam_quadric, beam_fit), else the beam "
        "quadric. Over bench_random seeds 1000-1099 at full rate the RMS of error over 1-sigma "
        "goes from 5.65 / 2.62 to 1.13 / 1.35 (translation / rotation), every routine, sensor "
        "set, error size and clock within 0.90-1.55; the calibrations are the same, five "
        "verdicts change: three runs 5.3-6.8 mm off now fail (one 7.0 mm off still passes), "
        "and two 2.1 and 2.9 mm off fail where the quadric lands 7.6 and 25 mm away (false "
        "fails 6 -> 8); a recording took about a third longer (35.0 -> 46.5 s) while the "
        "stage segmented every cloud again; it now takes the quadric's points from the beam "
        "quadric's own fit (seed 1003: the stage 4.21 -> 1.29 s, the same 1-sigma). On sparse "
        "clouds (set 1 with boxes at 5 % of the point rate) the two models lie further apart "
        "than the error: seeds 2 and 3, 2.7 and 4.6 mm off, fail on a 1-sigma of 8.5 and 8.9 mm "
        "(seed 0, 4.0 mm off, passes on 4.2 mm; at 10 % seeds 0-3 are 1.7-2.3 mm off, report "
        "1.2-3.1 mm and pass); see docs/method.md. None: left out",
    )
    method: Literal["jackknife", "formal"] = Field(
        default="jackknife",
        description="jackknife: leave-one-stop-out spread (needs three stops or more, else "
        "formal); formal: the inverse information alone, which the correlated residuals of a "
        "surface patch make several times too small",
    )


@dataclass(frozen=True)
class PoseUncertainty:
    """1-sigma of one LiDAR's `T_base_lidar`: translation (3,) m, rotation (3,) deg (see module),
    and the names of the DoF the data leave undetermined."""

    stddev_translation_m: NDArray[np.float64]
    stddev_rotation_deg: NDArray[np.float64]
    undetermined: tuple[str, ...]


@dataclass(frozen=True)
class SurfaceShift:
    """How far stage 4's solution moves on surfaces smoothed further (`shift` (P,), the
    optimiser's twists), and the covariance (P, P) that chance alone would give that shift
    (`chance`: a leave-one-stop-out jackknife of it; None with fewer than three stops)."""

    shift: NDArray[np.float64]
    chance: NDArray[np.float64] | None


def level_rotation(up_base: NDArray[np.float64]) -> NDArray[np.float64]:
    """`R_level_base` (3, 3): the smallest rotation taking the unit vector `up_base` to +z."""
    up = up_base / np.linalg.norm(up_base)
    axis = np.cross(up, [0.0, 0.0, 1.0])
    sin, cos = float(np.linalg.norm(axis)), float(up[2])
    if sin < 1e-12:
        return np.eye(3) if cos > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / sin
    K = hat(k)
    result: NDArray[np.float64] = np.eye(3) + sin * K + (1 - cos) * (K @ K)
    return result


def _prior(layout_size: int, config: ObservabilityConfig) -> NDArray[np.float64]:
    """The weak prior's information per parameter (P,): twists `[rho, phi]` per pose."""
    per_pose = [1.0 / config.prior_translation_m**2] * 3 + [
        1.0 / np.radians(config.prior_rotation_deg) ** 2
    ] * 3
    return np.tile(per_pose, layout_size // 6)


STOP_PRIOR_DILUTION = 1e-4
"""How much of the weak prior the stops keep when judging whether the data determine a LiDAR's
DoF (`_determination_prior`): enough to keep a stop nothing sees invertible, too little to
hold a LiDAR through the stops (a hundred stops moving with it weigh 0.01 of its own prior)."""


def _determination_prior(
    layout: ParameterLayout, config: ObservabilityConfig
) -> NDArray[np.float64]:
    """`_prior` with the stops' part diluted by `STOP_PRIOR_DILUTION`: the LiDARs alone hold
    "we know nothing". With the full prior on every stop, a LiDAR that the data leave free only
    together with a group of stops (the recording splits into parts no object ties together:
    a lane driven out and back, each LiDAR seeing one side each way, leaves the LiDAR's shift
    along the lane free with the return leg's stops, `bench_random` seed 1092) borrows the
    prior of all those stops, its stddev shrinks by their square root and it passes for
    determined."""
    prior = _prior(layout.size, config)
    stops = 6 * (layout.n_stops - 1)
    prior[:stops] *= STOP_PRIOR_DILUTION
    return prior


def jackknife_covariance(
    result: OptimisationResult, prior: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Leave-one-stop-out covariance (P, P) of the parameters, linearised at the solution.

    Without stop j the cost keeps every residual but those touching j: one Gauss-Newton step
    from the solution with `H - H_j` and `b - b_j` gives that solution's offset `d_j`; the
    jackknife covariance is `(n - 1) / n * sum_j (d_j - mean)(d_j - mean)^T` over the n stops
    with data. None with fewer than three such stops.
    """
    return leave_one_out_covariance(result, result.stop_information, result.stop_gradient, prior)


def block_jackknife_covariance(
    result: OptimisationResult, prior: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Leave-one-block-out covariance (P, P): as `jackknife_covariance`, leaving out in turn the
    point pairs whose target lies in one block of space (`result.block_information`). A
    surface's misfit that every stop repeats (its residuals correlated along the patch) moves
    the solution when its block is left out, which no stop's absence does. None with fewer
    than three blocks."""
    return leave_one_out_covariance(result, result.block_information, result.block_gradient, prior)


def leave_one_out_covariance(
    result: OptimisationResult,
    part_information: NDArray[np.float64],
    part_gradient: NDArray[np.float64],
    prior: NDArray[np.float64],
) -> NDArray[np.float64] | None:
    """Delete-one jackknife covariance (P, P) over the parts whose information (n, P, P) and
    gradient (n, P) are given: the offset of the solution without each part with data, from
    one Gauss-Newton step at the solution. None with fewer than three such parts."""
    size = result.layout.size
    H, b = result.information, result.gradient
    used = [
        j
        for j in range(len(part_information))
        if np.any(part_information[j]) or np.any(part_gradient[j])
    ]
    if len(used) < 3 or size == 0:
        return None
    offsets = np.empty((len(used), size))
    for row, j in enumerate(used):
        A = H - part_information[j] + np.diag(prior)
        offsets[row] = -np.linalg.solve(A, b - part_gradient[j])
    centred = offsets - offsets.mean(axis=0)
    n = len(used)
    covariance: NDArray[np.float64] = (n - 1) / n * (centred.T @ centred)
    return covariance


def shift_chance_covariance(
    before: OptimisationResult, after: OptimisationResult, config: ObservabilityConfig
) -> NDArray[np.float64] | None:
    """Leave-one-stop-out covariance (P, P) of the solution's shift from one objective to
    another, both evaluated at the same solution with the same kernel (`before`: the solution's
    own terms; `after`: another objective's there).

    Linearised, the shift is `-H^-1 (b' - b)` and without stop j it is
    `-(H - H_j)^-1 ((b' - b) - (b'_j - b_j))`: the jackknife of those offsets measures how much of
    the shift one stop or another brings, which a shift that every stop repeats (a systematic
    misfit) does not have. None with fewer than three stops with data."""
    prior = _prior(before.layout.size, config)
    difference = dataclasses.replace(before, gradient=after.gradient - before.gradient)
    return leave_one_out_covariance(
        difference, before.stop_information, after.stop_gradient - before.stop_gradient, prior
    )


def range_bias_estimate(
    result: OptimisationResult, prior: NDArray[np.float64], config: ObservabilityConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each LiDAR's range bias (L,) m as the data estimate it, and its 1-sigma (L,) m.

    The poses and one range bias per LiDAR solved together, one Gauss-Newton step from the
    solution (whose pose gradient is ~0): `[H + prior, C; C^T, D + prior_beta] [d; beta] =
    -[b; e]` with the terms of `assembly.range_bias_terms`, the weak prior of a translation on
    each bias. The 1-sigma is formal (the same system's inverse, a-posteriori variance)."""
    size, n_lidars = result.layout.size, result.layout.n_lidars
    if len(result.range_bias_cross) != n_lidars:
        raise ValueError("the optimisation ran without range_bias=True: no range-bias terms")
    bias_prior = np.full(n_lidars, 1.0 / config.prior_translation_m**2)
    C = result.range_bias_cross.T  # (P, L)
    system = np.block(
        [
            [result.information + np.diag(prior), C],
            [C.T, result.range_bias_information + np.diag(bias_prior)],
        ]
    )
    solution = -np.linalg.solve(
        system, np.concatenate([result.gradient, result.range_bias_gradient])
    )
    scale = 1.0 / max(result.variance_factor, 1e-12)
    scaled = np.block(
        [
            [result.information * scale + np.diag(prior), C * scale],
            [C.T * scale, result.range_bias_information * scale + np.diag(bias_prior)],
        ]
    )
    stddev = np.sqrt(np.clip(np.diag(np.linalg.inv(scaled))[size:], 0.0, None))
    beta: NDArray[np.float64] = solution[size:]
    return beta, stddev


def range_bias_covariance(
    result: OptimisationResult, prior: NDArray[np.float64], config: ObservabilityConfig
) -> NDArray[np.float64]:
    """(P, P) covariance of the poses under each LiDAR's range bias as large as the data
    estimate it (`range_bias_estimate`: |beta_i| and its 1-sigma together): a "consider"
    covariance `sum_i s_i^2 g_i g_i^T`, `g_i = -(H + prior)^-1 C_i` the solution's shift per
    metre of LiDAR i's bias, each LiDAR's taken on its own (their signs are not trusted).

    Why: a surface fitted under range noise sits off the true one by an amount that every stop
    and every neighbouring point repeat (curvature, density, the nearest-neighbour choice), so
    neither the formal covariance nor a jackknife sees it; along the rays it shows as a range
    bias, which rays meeting surfaces at many angles make measurable."""
    size = result.layout.size
    if size == 0:
        return np.zeros((0, 0))
    beta, beta_stddev = range_bias_estimate(result, prior, config)
    A = result.information + np.diag(prior)
    shifts = -np.linalg.solve(A, result.range_bias_cross.T)  # (P, L)
    weighted = shifts * np.hypot(beta, beta_stddev)[None, :]
    covariance: NDArray[np.float64] = weighted @ weighted.T
    return covariance


def _stddev(
    covariance: NDArray[np.float64], col: int, A: NDArray[np.float64]
) -> NDArray[np.float64]:
    """1-sigma (6,) of the pose whose twist starts at column `col`, in the axes of `A` (6, 6)."""
    block = covariance[col : col + 6, col : col + 6]
    result: NDArray[np.float64] = np.sqrt(np.clip(np.diag(A @ block @ A.T), 0.0, None))
    return result


def _beyond_chance(
    surface_shift: SurfaceShift, col: int, A: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(6,) the part of the pose's shift (twist at column `col`, in the axes of `A`) beyond its
    chance spread: `sqrt(max(0, s^2 - var))` per axis, all of it when chance is unknown."""
    shift = A @ surface_shift.shift[col : col + 6]
    chance = np.zeros(6) if surface_shift.chance is None else _stddev(surface_shift.chance, col, A)
    result: NDArray[np.float64] = np.sqrt(np.clip(shift**2 - chance**2, 0.0, None))
    return result


def _offset(T_level_lidar: Matrix4, T_level_other: Matrix4) -> NDArray[np.float64]:
    """(6,) the other pose of one LiDAR against this one in the axes of `PoseUncertainty`:
    its origin's shift in the level frame (m), then its rotation vector there (rad)."""
    rotation = make_transform(T_level_other[:3, :3] @ T_level_lidar[:3, :3].T, np.zeros(3))
    return np.concatenate([T_level_other[:3, 3] - T_level_lidar[:3, 3], log_se3(rotation)[3:]])


def pose_uncertainties(
    result: OptimisationResult,
    T_base_ref: Matrix4,
    up_ref: NDArray[np.float64] | None,
    config: ObservabilityConfig,
    surface_shift: SurfaceShift | None = None,
    alternative_T_ref_lidar: NDArray[np.float64] | None = None,
) -> tuple[PoseUncertainty, ...]:
    """Per LiDAR (reference first), from stage 4's result.

    Formal: the information `J^T W J` rescaled by the a-posteriori variance factor, plus the weak
    prior, inverted. Reported: the jackknifes' covariances (`config.method`), never below the
    formal one, and with them (in quadrature) the effect of each LiDAR's estimated range bias
    (`config.range_bias`) and the shift of the solution on surfaces smoothed further
    (`surface_shift`: per axis, the part of the shift beyond chance, `sqrt(max(0, s^2 -
    var_chance))`, the moment estimate of a systematic error), and each LiDAR's offset to
    `alternative_T_ref_lidar` (L, 4, 4), another solution the recording fits alike (the data
    cannot tell which of the two is the calibration, so the uncertainty spans both).
    Each LiDAR's 6x6 block is turned from the optimiser's twist (in the
    reference frame) into the level-base axes through the LiDAR's origin. `up_ref` (3,): the
    floor normal in the reference LiDAR's frame (None: use the base frame's axes as they are).
    The undetermined DoF are judged on the formal stddev with the stops' prior diluted
    (`_determination_prior`).
    """
    layout = result.layout
    prior = _prior(layout.size, config)
    scale = 1.0 / max(result.variance_factor, 1e-12)
    formal = np.asarray(np.linalg.inv(result.information * scale + np.diag(prior)), np.float64)
    determination = np.asarray(
        np.linalg.inv(result.information * scale + np.diag(_determination_prior(layout, config))),
        np.float64,
    )
    measured = (
        [
            c
            for c in (
                jackknife_covariance(result, prior),
                block_jackknife_covariance(result, prior),
            )
            if c is not None
        ]
        if config.method == "jackknife"
        else []
    )
    systematic = (
        range_bias_covariance(result, prior, config) if config.range_bias == "estimated" else None
    )
    R_level_base = np.eye(3) if up_ref is None else level_rotation(T_base_ref[:3, :3] @ up_ref)
    T_level_ref = make_transform(R_level_base, np.zeros(3)) @ T_base_ref
    limits = (
        np.array([config.prior_translation_m] * 3 + [np.radians(config.prior_rotation_deg)] * 3)
        * config.undetermined_fraction
    )
    results = [PoseUncertainty(np.zeros(3), np.zeros(3), ())]
    for lidar in range(1, layout.n_lidars):
        col = layout.lidar(lidar)
        T_level_lidar = T_level_ref @ result.T_ref_lidar[lidar]
        t = T_level_lidar[:3, 3]
        # A twist about the level frame's origin moves the LiDAR's origin by rho + phi x t.
        about_origin = np.eye(6)
        about_origin[:3, 3:] = -hat(t)
        A = about_origin @ adjoint(T_level_ref)

        undetermined = tuple(
            name
            for name, s, lim in zip(DOF_NAMES, _stddev(determination, col, A), limits, strict=True)
            if s > lim
        )
        stddev = _stddev(formal, col, A)
        for covariance in measured:
            stddev = np.maximum(stddev, _stddev(covariance, col, A))
        if systematic is not None:
            stddev = np.hypot(stddev, _stddev(systematic, col, A))
        if surface_shift is not None:
            stddev = np.hypot(stddev, _beyond_chance(surface_shift, col, A))
        if alternative_T_ref_lidar is not None:
            offset = _offset(T_level_lidar, T_level_ref @ alternative_T_ref_lidar[lidar])
            stddev = np.hypot(stddev, np.abs(offset))
        results.append(PoseUncertainty(stddev[:3], np.degrees(stddev[3:]), undetermined))
    return tuple(results)
