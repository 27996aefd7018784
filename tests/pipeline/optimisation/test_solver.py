from typing import Any

import numpy as np

from pipeline.geometry import log_se3
from pipeline.optimisation import OptimisationConfig, OptimisationResult, optimise
from pipeline.transforms import Points, invert, pose_difference
from tests.pipeline.calibration_data import box_problem, true_T_ref_lidar
from tests.pipeline.optimisation.inputs import StageInputs, stage_inputs


def _optimise(
    inputs: StageInputs, objects: list[list[Points]] | None = None, **options: Any
) -> OptimisationResult:
    """Stage 4 on the box problem from stage 3's poses, with the default config."""
    rough = inputs.rough
    return optimise(
        inputs.objects if objects is None else objects,
        rough.T_G_ref,
        rough.T_ref_lidar,
        OptimisationConfig(),
        planes=inputs.planes,
        floor_G=rough.floor_G,
        normals=inputs.normals,
        **options,
    )


def test_joint_optimisation_returns_the_extrinsics_to_the_truth() -> None:
    _, truth = box_problem()
    inputs = stage_inputs()
    rough = inputs.rough
    result = _optimise(inputs)
    T_true = true_T_ref_lidar(truth, tuple(lidar.frame for lidar in inputs.prepared.lidars))
    start = pose_difference(T_true[1], rough.T_ref_lidar[1])
    translation, rotation = pose_difference(T_true[1], result.T_ref_lidar[1])
    assert start[0] > 0.05
    assert translation < 0.01 and rotation < 0.1
    assert result.converged
    assert result.error_per_iteration[-1] < 0.5 * result.error_per_iteration[0]
    assert len(result.T_ref_lidar_per_iteration) == result.iterations + 1
    assert np.isfinite(result.information).all()


def _lengthened(clouds: list[list[Points]], lidar: int, metres: float) -> list[list[Points]]:
    """`clouds` with LiDAR `lidar`'s points moved `metres` further along their rays."""
    out = [list(row) for row in clouds]
    out[lidar] = [p + metres * p / np.linalg.norm(p, axis=1, keepdims=True) for p in out[lidar]]
    return out


def test_a_range_bias_moves_the_solution_as_its_gradient_predicts() -> None:
    # Each LiDAR's surfaces set 5 mm further along its rays: the solution moves by about
    # -(H + prior)^-1 db/dbeta x 5 mm, the shift the observability stage charges to a bias.
    inputs = stage_inputs()

    def solve(objects: list[list[Points]]) -> OptimisationResult:
        return _optimise(inputs, objects, range_bias=True)

    base = solve(inputs.objects)
    assert base.range_bias_cross.shape == (base.layout.n_lidars, base.layout.size)
    prior = np.full(base.layout.size, 1e-6)
    col = base.layout.lidar(1)
    for lidar in range(base.layout.n_lidars):
        A = base.information + np.diag(prior)
        predicted = -np.linalg.solve(A, base.range_bias_cross[lidar])[col : col + 6] * 0.005
        biased = solve(_lengthened(inputs.objects, lidar, 0.005))
        # The optimiser's twist is on the left, in the reference frame.
        moved = log_se3(biased.T_ref_lidar[1] @ invert(base.T_ref_lidar[1]))
        assert np.linalg.norm(predicted[:3]) > 0.001
        assert np.linalg.norm(moved[:3] - predicted[:3]) < 0.3 * np.linalg.norm(predicted[:3])
