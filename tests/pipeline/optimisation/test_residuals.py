import numpy as np
import pytest

from pipeline.optimisation import RobustLoss
from pipeline.optimisation.residuals import robust_weight_and_cost


@pytest.mark.parametrize("loss", ["cauchy", "huber", "none"])
def test_the_irls_weight_is_the_cost_slope_over_the_distance(loss: RobustLoss) -> None:
    distance = np.array([1e-3, 0.02, 0.05, 0.09, 0.3, 2.0])
    scale, h = 0.1, 1e-7
    weight, cost = robust_weight_and_cost(distance, scale, loss)
    _, plus = robust_weight_and_cost(distance + h, scale, loss)
    _, minus = robust_weight_and_cost(distance - h, scale, loss)
    np.testing.assert_allclose(weight, (plus - minus) / (2 * h) / distance, rtol=1e-5)
    # Quadratic at zero: rho(s) ~ s^2 / 2.
    assert cost[0] == pytest.approx(0.5 * distance[0] ** 2, rel=1e-3)
