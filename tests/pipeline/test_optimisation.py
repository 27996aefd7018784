from typing import Any

import numpy as np
import pytest

from pipeline.optimisation import (
    OptimisationConfig,
    ResidualKind,
    _apply_step,
    _Problem,
    optimise,
)
from pipeline.rough_refinement import RoughRefinementConfig, refine_with_floor
from pipeline.transforms import pose_difference
from tests.pipeline.calibration_data import box_prepared, box_problem, true_T_ref_lidar


def _stage_inputs() -> tuple[Any, ...]:
    prepared, segments = box_prepared()
    planes = [[s.floor for s in row] for row in segments]
    rough = refine_with_floor(
        planes, prepared.T_G_ref, prepared.T_ref_lidar, RoughRefinementConfig()
    )
    objects = [[s.object_points for s in row] for row in segments]
    normals = [[s.object_normals for s in row] for row in segments]
    return prepared, planes, rough, objects, normals


@pytest.mark.parametrize("residual", ["point_to_plane", "point_to_point"])
@pytest.mark.parametrize("every_lidar", [False, True])
def test_normal_equations_hold_the_cost_gradient(residual: ResidualKind, every_lidar: bool) -> None:
    _, planes, rough, objects, normals = _stage_inputs()
    config = OptimisationConfig(
        residual=residual, max_points_per_cloud=60, lidar_self_consistency=every_lidar
    )
    problem = _Problem(objects, planes, rough.floor_G, len(rough.T_G_ref), config, normals)
    stops, lidars, scale = rough.T_G_ref, rough.T_ref_lidar, 0.05
    pairs = problem.associate(problem.place(stops, lidars))
    _, gradient, _, _ = problem.normal_equations(pairs, stops, lidars, scale)
    numeric = np.zeros_like(gradient)
    for k in range(len(gradient)):
        step = np.zeros_like(gradient)
        step[k] = 1e-6
        plus = problem.cost(pairs, *_apply_step(step, problem.layout, stops, lidars), scale)
        minus = problem.cost(pairs, *_apply_step(-step, problem.layout, stops, lidars), scale)
        numeric[k] = (plus - minus) / 2e-6
    assert np.max(np.abs(numeric - gradient)) < 1e-5 * np.max(np.abs(gradient))


def test_joint_optimisation_returns_the_extrinsics_to_the_truth() -> None:
    _, truth = box_problem()
    prepared, planes, rough, objects, normals = _stage_inputs()
    result = optimise(
        objects,
        rough.T_G_ref,
        rough.T_ref_lidar,
        OptimisationConfig(),
        planes=planes,
        floor_G=rough.floor_G,
        normals=normals,
    )
    T_true = true_T_ref_lidar(truth, tuple(lidar.frame for lidar in prepared.lidars))
    start = pose_difference(T_true[1], rough.T_ref_lidar[1])
    translation, rotation = pose_difference(T_true[1], result.T_ref_lidar[1])
    assert start[0] > 0.05
    assert translation < 0.01 and rotation < 0.1
    assert result.converged
    assert result.error_per_iteration[-1] < 0.5 * result.error_per_iteration[0]
    assert len(result.T_ref_lidar_per_iteration) == result.iterations + 1
    assert np.isfinite(result.information).all()
