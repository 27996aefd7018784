import numpy as np
import pytest

from pipeline.optimisation import OptimisationConfig, ResidualKind
from pipeline.optimisation.assembly import block_contributions, normal_equations
from pipeline.optimisation.association import associate
from pipeline.optimisation.layout import ParameterLayout, apply_step
from pipeline.optimisation.objective import JointObjective
from pipeline.optimisation.residuals import cost
from tests.pipeline.optimisation.inputs import stage_inputs


@pytest.mark.parametrize("residual", ["point_to_plane", "point_to_point"])
@pytest.mark.parametrize("every_lidar", [False, True])
@pytest.mark.parametrize("stop_prior", [False, True])
def test_normal_equations_hold_the_cost_gradient(
    residual: ResidualKind, every_lidar: bool, stop_prior: bool
) -> None:
    inputs = stage_inputs()
    rough = inputs.rough
    config = OptimisationConfig(
        residual=residual,
        max_points_per_cloud=60,
        lidar_self_consistency=every_lidar,
        stop_prior_sigma_m=0.05,
        stop_prior_sigma_deg=2.0,
    )
    stops, lidars, scale = rough.T_G_ref, rough.T_ref_lidar, 0.05
    # The prior's anchor off the poses, so that its terms pull.
    size = 6 * (len(stops) - 1 + len(lidars) - 1)
    twist = np.random.default_rng(0).normal(scale=0.03, size=size)
    layout = ParameterLayout(len(stops), len(lidars))
    anchor = apply_step(twist, layout, stops, lidars)[0] if stop_prior else None
    objective = JointObjective.build(
        inputs.objects, inputs.planes, rough.floor_G, len(stops), config, inputs.normals, anchor
    )
    pairs = associate(objective, objective.place(stops, lidars))
    _, gradient, _, _ = normal_equations(objective, pairs, stops, lidars, scale)
    numeric = np.zeros_like(gradient)
    for k in range(len(gradient)):
        step = np.zeros_like(gradient)
        step[k] = 1e-6
        plus = cost(objective, pairs, *apply_step(step, objective.layout, stops, lidars), scale)
        minus = cost(objective, pairs, *apply_step(-step, objective.layout, stops, lidars), scale)
        numeric[k] = (plus - minus) / 2e-6
    assert np.max(np.abs(numeric - gradient)) < 1e-5 * np.max(np.abs(gradient))


@pytest.mark.parametrize("block_m", [0.2, 1.0])
def test_the_blocks_of_space_partition_the_point_pairs(block_m: float) -> None:
    # Every pair falls in exactly one block: without floor terms the blocks' information and
    # gradients add up to the whole problem's, and a finer grid gives more blocks.
    inputs = stage_inputs()
    rough = inputs.rough
    config = OptimisationConfig(max_points_per_cloud=200)
    objective = JointObjective.build(
        inputs.objects, inputs.planes, rough.floor_G, len(rough.T_G_ref), config, inputs.normals
    )
    stops, lidars, scale = rough.T_G_ref, rough.T_ref_lidar, 0.05
    pairs = associate(objective, objective.place(stops, lidars))
    H, b, _, _ = normal_equations(objective, pairs, stops, lidars, scale, with_floor=False)
    block_H, block_b = block_contributions(objective, pairs, stops, lidars, scale, block_m)
    assert len(block_H) >= 3
    np.testing.assert_allclose(block_H.sum(axis=0), H, rtol=1e-9, atol=1e-6 * np.abs(H).max())
    np.testing.assert_allclose(block_b.sum(axis=0), b, rtol=1e-9, atol=1e-6 * np.abs(b).max())
    if block_m < 1.0:
        coarse, _ = block_contributions(objective, pairs, stops, lidars, scale, 1.0)
        assert len(block_H) > len(coarse)
