"""The solver: phases of Levenberg-Marquardt steps with the associations redone after each step,
then the information at the solution."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from pipeline.geometry import Plane
from pipeline.optimisation.acceleration import AndersonAcceleration
from pipeline.optimisation.assembly import (
    block_contributions,
    normal_equations,
    range_bias_terms,
    stop_contributions,
)
from pipeline.optimisation.association import Pairs, associate
from pipeline.optimisation.config import OptimisationConfig
from pipeline.optimisation.layout import apply_step
from pipeline.optimisation.objective import JointObjective, PlacedClouds
from pipeline.optimisation.pair_noise import with_lidar_pair_sigmas
from pipeline.optimisation.residuals import (
    cost,
    point_residuals,
    robust_sigma,
    whitened_residuals,
)
from pipeline.optimisation.result import OptimisationResult
from pipeline.transforms import Points


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
    range_bias: bool = False,
) -> OptimisationResult:
    """Refine the poses so every LiDAR's object map agrees with the reference LiDAR's.

    `objects[lidar][stop]`: (N, 3) object points in that LiDAR's frame; LiDAR 0 is the reference.
    `T_G_ref` (J, 4, 4): the reference's pose per stop (stop 0 fixed). `T_ref_lidar` (L, 4, 4):
    extrinsics relative to the reference (index 0 is the identity, fixed). `planes[lidar][stop]`
    and `floor_G` (stage 3) add the floor terms; without them only the objects count.
    `normals[lidar][stop]` (N, 3): the points' surface normals when the caller has them
    (segmentation does); without them they are fitted here, and the clouds smoothed if
    `smooth_clouds`. `on_iteration(k)` is called after iteration k (progress for a caller).
    `range_bias`: also return the terms of a range bias per LiDAR (`assembly.range_bias_terms`,
    for `observability.range_bias: estimated`); without it they are empty (0 LiDARs' worth).
    """
    started = time.perf_counter()
    phases = _phases(objects, planes, floor_G, T_G_ref, config, normals)
    run = _Run.start(T_G_ref, T_ref_lidar, config, config.kernel_scale_min_m)
    for phase, objective in enumerate(phases):
        _iterate(run, objective, config, last=phase == len(phases) - 1, on_iteration=on_iteration)
    return _result(phases[-1], run, started, range_bias)


def _phases(
    objects: Sequence[Sequence[Points]],
    planes: Sequence[Sequence[Plane | None]] | None,
    floor_G: Plane | None,
    start_G_ref: NDArray[np.float64],
    config: OptimisationConfig,
    normals: Sequence[Sequence[Points]] | None,
    *,
    final_only: bool = False,
) -> list[JointObjective]:
    """The objective of each phase: a coarse one on `coarse_points_per_cloud` points when that is
    fewer than the final phase's, then the final one (normal gate `fine_max_normal_angle_deg`, loss
    `fine_robust_loss`); `final_only`: the final one alone. The stops' prior (where the config
    sets one) holds them at `start_G_ref`."""
    n_stops = len(start_G_ref)
    fine_config = config.model_copy(
        update={
            "max_normal_angle_deg": config.fine_max_normal_angle_deg,
            "robust_loss": config.fine_robust_loss or config.robust_loss,
        }
    )
    phases = [
        JointObjective.build(objects, planes, floor_G, n_stops, fine_config, normals, start_G_ref)
    ]
    coarse_cap = config.coarse_points_per_cloud
    if (
        not final_only
        and coarse_cap is not None
        and (config.max_points_per_cloud is None or coarse_cap < config.max_points_per_cloud)
    ):
        coarse_config = config.model_copy(update={"max_points_per_cloud": coarse_cap})
        phases.insert(
            0,
            JointObjective.build(
                objects, planes, floor_G, n_stops, coarse_config, normals, start_G_ref
            ),
        )
    return phases


def evaluate_at(
    objects: Sequence[Sequence[Points]],
    T_G_ref: NDArray[np.float64],
    T_ref_lidar: NDArray[np.float64],
    config: OptimisationConfig,
    *,
    kernel_scale_m: float,
    planes: Sequence[Sequence[Plane | None]] | None = None,
    floor_G: Plane | None = None,
    normals: Sequence[Sequence[Points]] | None = None,
    stop_anchor: NDArray[np.float64] | None = None,
) -> OptimisationResult:
    """What `optimise` would return at these poses without moving them (no iterations): the
    final phase's associations and normal equations there, the robust kernel at
    `kernel_scale_m`. Given a solution's own `kernel_scale_m`, it compares other clouds (the same
    scene segmented otherwise) with that solution's terms, term for term. `stop_anchor`: where
    the stops' prior holds them (the solution's own start, to reproduce its information to the
    bit); None: at `T_G_ref`, which differs from the start only in the prior's rotation
    Jacobian (the inverse left Jacobian at the stop's turn since the start, degrees at most,
    against a prior of 30 deg)."""
    started = time.perf_counter()
    anchor = T_G_ref if stop_anchor is None else stop_anchor
    (objective,) = _phases(objects, planes, floor_G, anchor, config, normals, final_only=True)
    run = _Run.start(T_G_ref, T_ref_lidar, config, kernel_scale_m)
    return _result(objective, run, started, range_bias=False)


@dataclass
class _Run:
    """The poses and the record of one optimisation, carried across its phases."""

    stops: NDArray[np.float64]
    lidars: NDArray[np.float64]
    history: list[NDArray[np.float64]]  # T_ref_lidar before each step and at the end
    damping: float  # Levenberg-Marquardt lambda
    scale: float  # the robust kernel's scale at the last step
    errors: list[float] = field(default_factory=list)
    converged: bool = False
    iteration: int = 0
    accelerated: int = 0  # steps Anderson acceleration extrapolated

    @classmethod
    def start(
        cls,
        T_G_ref: NDArray[np.float64],
        T_ref_lidar: NDArray[np.float64],
        config: OptimisationConfig,
        scale: float,
    ) -> _Run:
        """A run at these poses (copied), before any step."""
        lidars = np.array(T_ref_lidar, dtype=np.float64)
        return cls(
            stops=np.array(T_G_ref, dtype=np.float64),
            lidars=lidars,
            history=[lidars.copy()],
            damping=config.initial_damping,
            scale=scale,
        )


def _iterate(
    run: _Run,
    objective: JointObjective,
    config: OptimisationConfig,
    *,
    last: bool,
    on_iteration: Callable[[int], None] | None,
) -> None:
    """One phase's steps, each with fresh associations, until the poses stop moving or the
    iterations run out; `run` is updated in place."""
    tolerance = (
        (config.translation_tolerance_m, config.rotation_tolerance_deg)
        if last
        else (config.coarse_translation_tolerance_m, config.coarse_rotation_tolerance_deg)
    )
    run.converged = False
    placed = objective.place(run.stops, run.lidars)
    pairs = _associate(objective, placed)
    anderson = AndersonAcceleration(
        objective.layout, (run.stops, run.lidars), config.anderson_depth
    )
    while run.iteration < config.max_iterations:
        run.iteration += 1
        run.errors.append(pairs.cross_error)
        # Graduated robustness: wide at first, while everything is far off, then tight so
        # that parts one LiDAR saw and the reference did not stop pulling.
        floor = kernel_scale_floor(objective, pairs, placed)
        run.scale = max(
            floor, config.kernel_scale_initial_m * config.kernel_scale_decay ** (run.iteration - 1)
        )
        before = (run.stops, run.lidars)
        run.stops, run.lidars, moved, run.damping = lm_step(
            objective, pairs, run.stops, run.lidars, run.scale, run.damping, placed
        )
        placed = objective.place(run.stops, run.lidars)
        pairs = _associate(objective, placed)
        if config.acceleration == "anderson" and last and run.scale <= floor and moved is not None:
            # Only at the final kernel: before it the map x -> G(x) changes every step.
            proposed = anderson.propose(before, (run.stops, run.lidars))
            if proposed is not None:
                proposed_placed = objective.place(*proposed)
                proposed_pairs = _associate(objective, proposed_placed)
                plain = cost(objective, pairs, run.stops, run.lidars, run.scale, placed)
                if cost(objective, proposed_pairs, *proposed, run.scale, proposed_placed) < plain:
                    run.stops, run.lidars = proposed
                    placed, pairs = proposed_placed, proposed_pairs
                    moved = _motion(objective, before, proposed)
                    run.accelerated += 1
                else:
                    anderson.keep_last()
        run.history.append(run.lidars.copy())
        if on_iteration is not None:
            on_iteration(run.iteration)
        if moved is None or (
            moved[0] < tolerance[0] and moved[1] < tolerance[1] and (not last or run.scale <= floor)
        ):
            run.converged = True
            break


def _associate(objective: JointObjective, placed: PlacedClouds) -> Pairs:
    """The pairs at the poses `placed`, with their sigmas where `pair_weights` measures them."""
    pairs = associate(objective, placed)
    if objective.config.pair_weights == "lidar_pairs":
        return with_lidar_pair_sigmas(objective, pairs, placed)
    return pairs


def kernel_scale_floor(objective: JointObjective, pairs: Pairs, placed: PlacedClouds) -> float:
    """The smallest robust kernel scale (m) for the next step: `kernel_scale_min_m`, or
    `kernel_scale_min_sigmas` robust standard deviations of the residuals of `pairs` at the poses
    `placed` when that is wider."""
    config = objective.config
    if config.kernel_scale_min_sigmas is None or len(pairs.source) == 0:
        return config.kernel_scale_min_m
    residual = point_residuals(config.residual, pairs, placed)
    sigma = robust_sigma(whitened_residuals(pairs, residual, config.point_sigma_m))
    return max(config.kernel_scale_min_m, config.kernel_scale_min_sigmas * sigma)


def _result(
    objective: JointObjective, run: _Run, started: float, range_bias: bool
) -> OptimisationResult:
    """The result at the final poses, with the final phase's associations there: the
    information matrix, the per-stop parts of it and the variance factor."""
    layout, stops, lidars = objective.layout, run.stops, run.lidars
    placed = objective.place(stops, lidars)
    pairs = _associate(objective, placed)
    run.errors.append(pairs.cross_error)
    H = np.zeros((layout.size, layout.size))
    gradient = np.zeros(layout.size)
    chi2, count = 0.0, 0
    if len(pairs.source) or objective.floor:
        H, gradient, chi2, count = normal_equations(
            objective, pairs, stops, lidars, run.scale, ideal_floor=True, placed=placed
        )
    stop_H, stop_b = stop_contributions(objective, pairs, stops, lidars, run.scale, placed)
    block_H, block_b = block_contributions(
        objective, pairs, stops, lidars, run.scale, objective.config.uncertainty_block_m, placed
    )
    bias_cross, bias_information, bias_gradient = (
        range_bias_terms(objective, pairs, stops, lidars, run.scale, placed)
        if range_bias
        else (np.zeros((0, layout.size)), np.zeros((0, 0)), np.zeros(0))
    )
    redundancy = max(count - layout.size, 1)
    residual_rms = float("nan")
    if len(pairs.source):
        residual = point_residuals(objective.config.residual, pairs, placed)
        residual_rms = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
    per_lidar = np.bincount(objective.sources.lidar[pairs.source], minlength=layout.n_lidars)
    return OptimisationResult(
        T_G_ref=stops,
        T_ref_lidar=lidars,
        converged=run.converged,
        iterations=run.iteration,
        error_per_iteration=tuple(run.errors),
        T_ref_lidar_per_iteration=np.stack(run.history),
        information=H,
        gradient=gradient,
        stop_information=stop_H,
        stop_gradient=stop_b,
        block_information=block_H,
        block_gradient=block_b,
        range_bias_cross=bias_cross,
        range_bias_information=bias_information,
        range_bias_gradient=bias_gradient,
        variance_factor=chi2 / redundancy,
        layout=layout,
        correspondences=tuple(int(c) for c in per_lidar),
        residual_rms_m=residual_rms,
        seconds=time.perf_counter() - started,
        kernel_scale_m=run.scale,
        accelerated_steps=run.accelerated,
    )


def _largest_motion(before: NDArray[np.float64], after: NDArray[np.float64]) -> tuple[float, float]:
    """Largest translation (m) and rotation (deg) between matching poses of two (N, 4, 4) stacks."""
    delta = np.linalg.inv(before) @ after
    translation = float(np.max(np.linalg.norm(after[:, :3, 3] - before[:, :3, 3], axis=1)))
    cos = np.clip((np.trace(delta[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)
    return translation, float(np.degrees(np.max(np.arccos(cos))))


def _motion(
    objective: JointObjective,
    before: tuple[NDArray[np.float64], NDArray[np.float64]],
    after: tuple[NDArray[np.float64], NDArray[np.float64]],
) -> tuple[float, float]:
    """The largest motion (m, deg) from `before` to `after` (stops, LiDARs) of the poses
    convergence is judged on (`OptimisationConfig.converge_on`)."""
    moved = _largest_motion(before[1], after[1])
    if objective.config.converge_on == "all_poses" or objective.layout.n_lidars == 1:
        stop_motion = _largest_motion(before[0], after[0])
        moved = (max(stop_motion[0], moved[0]), max(stop_motion[1], moved[1]))
    return moved


def lm_step(
    objective: JointObjective,
    pairs: Pairs,
    stops: NDArray[np.float64],
    lidars: NDArray[np.float64],
    scale: float,
    damping: float,
    placed: PlacedClouds | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[float, float] | None, float]:
    """One Levenberg-Marquardt step with fixed associations: the new poses, the largest motion
    (m, deg) of the poses convergence is judged on (`OptimisationConfig.converge_on`; None when
    no step lowered the cost) and the new damping. `placed`: the clouds placed with `stops` and
    `lidars`, where the caller has them (the pairs were found there)."""
    layout = objective.layout
    if placed is None:
        placed = objective.place(stops, lidars)
    H, b, _, _ = normal_equations(objective, pairs, stops, lidars, scale, placed=placed)
    before = cost(objective, pairs, stops, lidars, scale, placed)
    # A pose nothing constrains (no objects, no floor) keeps its value instead of a singular
    # solve; the observability stage reports it.
    floor = 1e-12 * max(float(np.trace(H)) / max(layout.size, 1), 1.0)
    for _ in range(10):
        A = H + damping * np.diag(np.diag(H)) + floor * np.eye(layout.size)
        step = np.asarray(-np.linalg.solve(A, b), dtype=np.float64)
        trial_stops, trial_lidars = apply_step(step, layout, stops, lidars)
        if cost(objective, pairs, trial_stops, trial_lidars, scale) <= before:
            moved = _motion(objective, (stops, lidars), (trial_stops, trial_lidars))
            return trial_stops, trial_lidars, moved, max(damping / 3.0, 1e-9)
        damping = max(damping * 4.0, 1e-6)
    return stops, lidars, None, damping
