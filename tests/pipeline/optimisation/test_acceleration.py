import numpy as np

from pipeline.geometry import exp_se3
from pipeline.optimisation.acceleration import AndersonAcceleration
from pipeline.optimisation.layout import ParameterLayout


def _start(layout: ParameterLayout) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    stops = np.stack([exp_se3(rng.normal(0.0, 0.3, 6)) for _ in range(layout.n_stops)])
    lidars = np.stack([exp_se3(rng.normal(0.0, 0.3, 6)) for _ in range(layout.n_lidars)])
    return stops, lidars


def test_twists_and_poses_are_inverse_and_leave_the_fixed_poses_alone() -> None:
    layout = ParameterLayout(n_stops=3, n_lidars=2)
    start = _start(layout)
    anderson = AndersonAcceleration(layout, start, depth=3)
    x = np.random.default_rng(4).normal(0.0, 0.1, layout.size)
    stops, lidars = anderson.poses(x)
    np.testing.assert_allclose(anderson.twists((stops, lidars)), x, atol=1e-12)
    np.testing.assert_array_equal(stops[0], start[0][0])
    np.testing.assert_array_equal(lidars[0], start[1][0])
    np.testing.assert_allclose(anderson.twists(start), 0.0, atol=1e-15)


def test_it_finds_the_fixed_point_of_a_slow_linear_iteration_in_a_few_steps() -> None:
    # x -> G(x) = A x + b contracting by 0.99 a step along one direction: plain iteration needs
    # hundreds of steps to get within 1e-6 of the fixed point, Anderson with a history as deep
    # as the space is long finds it as soon as the history spans the space.
    layout = ParameterLayout(n_stops=1, n_lidars=2)  # one free pose: P = 6
    rng = np.random.default_rng(5)
    basis, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    A = basis @ np.diag([0.99, 0.9, 0.5, 0.5, 0.3, 0.1]) @ basis.T
    b = rng.normal(0.0, 0.01, 6)
    fixed = np.linalg.solve(np.eye(6) - A, b)
    anderson = AndersonAcceleration(layout, _start(layout), depth=6)
    x = np.zeros(6)
    for _ in range(12):
        g = A @ x + b
        proposed = anderson.propose(anderson.poses(x), anderson.poses(g))
        x = g if proposed is None else anderson.twists(proposed)
    assert np.linalg.norm(x - fixed) < 1e-6 * np.linalg.norm(fixed)
    plain = np.zeros(6)
    for _ in range(12):
        plain = A @ plain + b
    assert np.linalg.norm(plain - fixed) > 0.05 * np.linalg.norm(fixed)


def test_keep_last_forgets_all_but_the_last_step() -> None:
    layout = ParameterLayout(n_stops=2, n_lidars=2)
    start = _start(layout)
    anderson = AndersonAcceleration(layout, start, depth=4)
    assert anderson.propose(start, anderson.poses(np.full(layout.size, 0.01))) is None
    assert anderson.propose(anderson.poses(np.full(layout.size, 0.01)), start) is not None
    anderson.keep_last()
    assert len(anderson.inputs) == len(anderson.outputs) == 1
