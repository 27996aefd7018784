import numpy as np
import pytest

from pipeline.optimisation import OptimisationConfig, ResidualKind
from pipeline.optimisation.assembly import normal_equations
from pipeline.optimisation.association import associate
from pipeline.optimisation.objective import JointObjective
from pipeline.optimisation.residuals import cost
from pipeline.optimisation.solver import apply_step
from tests.pipeline.optimisation.inputs import stage_inputs


@pytest.mark.parametrize("residual", ["point_to_plane", "point_to_point"])
@pytest.mark.parametrize("every_lidar", [False, True])
def test_normal_equations_hold_the_cost_gradient(residual: ResidualKind, every_lidar: bool) -> None:
    inputs = stage_inputs()
    rough = inputs.rough
    config = OptimisationConfig(
        residual=residual, max_points_per_cloud=60, lidar_self_consistency=every_lidar
    )
    objective = JointObjective.build(
        inputs.objects, inputs.planes, rough.floor_G, len(rough.T_G_ref), config, inputs.normals
    )
    stops, lidars, scale = rough.T_G_ref, rough.T_ref_lidar, 0.05
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
