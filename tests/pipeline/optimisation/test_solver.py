import numpy as np

from pipeline.optimisation import OptimisationConfig, optimise
from pipeline.transforms import pose_difference
from tests.pipeline.calibration_data import box_problem, true_T_ref_lidar
from tests.pipeline.optimisation.inputs import stage_inputs


def test_joint_optimisation_returns_the_extrinsics_to_the_truth() -> None:
    _, truth = box_problem()
    inputs = stage_inputs()
    rough = inputs.rough
    result = optimise(
        inputs.objects,
        rough.T_G_ref,
        rough.T_ref_lidar,
        OptimisationConfig(),
        planes=inputs.planes,
        floor_G=rough.floor_G,
        normals=inputs.normals,
    )
    T_true = true_T_ref_lidar(truth, tuple(lidar.frame for lidar in inputs.prepared.lidars))
    start = pose_difference(T_true[1], rough.T_ref_lidar[1])
    translation, rotation = pose_difference(T_true[1], result.T_ref_lidar[1])
    assert start[0] > 0.05
    assert translation < 0.01 and rotation < 0.1
    assert result.converged
    assert result.error_per_iteration[-1] < 0.5 * result.error_per_iteration[0]
    assert len(result.T_ref_lidar_per_iteration) == result.iterations + 1
    assert np.isfinite(result.information).all()
