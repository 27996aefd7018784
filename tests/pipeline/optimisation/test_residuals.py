import numpy as np
import pytest

from pipeline.optimisation import OptimisationConfig, RobustLoss
from pipeline.optimisation.objective import JointObjective
from pipeline.optimisation.residuals import floor_terms, robust_sigma, robust_weight_and_cost
from tests.pipeline.optimisation.inputs import stage_inputs


@pytest.mark.parametrize("loss", ["cauchy", "geman_mcclure", "huber", "none"])
def test_the_irls_weight_is_the_cost_slope_over_the_distance(loss: RobustLoss) -> None:
    distance = np.array([1e-3, 0.02, 0.05, 0.09, 0.3, 2.0])
    scale, h = 0.1, 1e-7
    weight, cost = robust_weight_and_cost(distance, scale, loss)
    _, plus = robust_weight_and_cost(distance + h, scale, loss)
    _, minus = robust_weight_and_cost(distance - h, scale, loss)
    np.testing.assert_allclose(weight, (plus - minus) / (2 * h) / distance, rtol=1e-5)
    # Quadratic at zero: rho(s) ~ s^2 / 2.
    assert cost[0] == pytest.approx(0.5 * distance[0] ** 2, rel=1e-3)


def test_geman_mcclure_stops_pulling_where_cauchy_still_pulls() -> None:
    # The pull (weight x distance) at ten kernel scales, against the pull at one scale.
    scale = 0.015
    distance = np.array([scale, 10 * scale])
    pulls = {}
    for loss in ("cauchy", "geman_mcclure"):
        weight, _ = robust_weight_and_cost(distance, scale, loss)
        pull = weight * distance
        pulls[loss] = pull[1] / pull[0]
    assert pulls["cauchy"] > 0.15
    assert pulls["geman_mcclure"] < 0.05


@pytest.mark.parametrize("dimensions", [1, 3])
def test_the_robust_sigma_of_residuals_ignores_a_third_of_outliers(dimensions: int) -> None:
    rng = np.random.default_rng(0)
    inliers = rng.normal(0.0, 0.008, size=(7000, dimensions))
    outliers = rng.uniform(-0.5, 0.5, size=(3000, dimensions))
    sigma = robust_sigma(np.vstack([inliers, outliers]))
    # Wild outliers (0.29 m of spread) move the median out a little, never to their spread.
    assert 0.008 < sigma < 0.008 * 2
    assert robust_sigma(inliers) == pytest.approx(0.008, rel=0.05)
    assert np.isnan(robust_sigma(np.zeros((0, dimensions))))


@pytest.mark.parametrize("ideal", [False, True])
def test_one_stops_floor_terms_are_its_rows_of_every_stops(ideal: bool) -> None:
    # The per-stop jackknife asks for one stop's floor terms alone: the same rows, to the bit,
    # as every stop's terms would give, in the objective's order.
    inputs = stage_inputs()
    rough = inputs.rough
    objective = JointObjective.build(
        inputs.objects,
        inputs.planes,
        rough.floor_G,
        len(rough.T_G_ref),
        OptimisationConfig(max_points_per_cloud=60),
        inputs.normals,
    )
    stops, lidars = rough.T_G_ref, rough.T_ref_lidar
    every, every_jac = floor_terms(objective, stops, lidars, jacobians=True, ideal=ideal)
    for stop in range(len(stops)):
        rows = [seen_at == stop for _, seen_at, _ in objective.floor]
        assert any(rows)
        one, one_jac = floor_terms(objective, stops, lidars, jacobians=True, ideal=ideal, stop=stop)
        np.testing.assert_array_equal(one, every[rows])
        np.testing.assert_array_equal(one_jac, every_jac[rows])
