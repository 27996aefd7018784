import dataclasses

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from pipeline.calibrate import calibrate
from pipeline.config import PipelineConfig
from pipeline.observability import (
    ObservabilityConfig,
    block_jackknife_covariance,
    jackknife_covariance,
    level_rotation,
    pose_uncertainties,
)
from pipeline.optimisation import OptimisationResult, ParameterLayout
from pipeline.transforms import make_transform
from tests.pipeline.calibration_data import (
    box_calibration,
    box_problem,
    dense_box_calibration,
    floor_only_calibration,
)


def _result(
    layout: ParameterLayout,
    T_ref_lidar: NDArray[np.float64],
    stop_information: NDArray[np.float64],
    stop_gradient: NDArray[np.float64],
) -> OptimisationResult:
    """A stage 4 result at `T_ref_lidar` (every stop pose at G) whose information and gradient
    are the sums of the stops' (S, P, P) and (S, P)."""
    size = layout.size
    return OptimisationResult(
        T_G_ref=np.tile(np.eye(4), (layout.n_stops, 1, 1)),
        T_ref_lidar=T_ref_lidar,
        converged=True,
        iterations=1,
        error_per_iteration=(0.0,),
        T_ref_lidar_per_iteration=T_ref_lidar[None],
        information=stop_information.sum(axis=0),
        gradient=stop_gradient.sum(axis=0),
        stop_information=stop_information,
        stop_gradient=stop_gradient,
        block_information=np.zeros((0, size, size)),
        block_gradient=np.zeros((0, size)),
        range_bias_cross=np.zeros((layout.n_lidars, size)),
        range_bias_information=np.zeros((layout.n_lidars, layout.n_lidars)),
        range_bias_gradient=np.zeros(layout.n_lidars),
        variance_factor=1.0,
        layout=layout,
        correspondences=(0, 0),
        residual_rms_m=0.0,
        seconds=0.0,
        kernel_scale_m=0.015,
    )


def test_level_rotation_turns_the_floor_normal_to_z_by_the_shortest_way() -> None:
    up = np.array([0.1, -0.05, 1.0])
    R = level_rotation(up)
    np.testing.assert_allclose(R @ (up / np.linalg.norm(up)), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    # No turn about z: the horizontal axis orthogonal to the tilt stays put.
    axis = np.cross(up, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(R @ axis, axis, atol=1e-12)


def test_objects_determine_every_degree_of_freedom() -> None:
    # Twice the sparse fixture's rate: at 5 % the surfaces' two models place the rear LiDAR
    # 7 mm apart, and the 1-sigma says so (a fact of sparse clouds, not of determination).
    result = dense_box_calibration()
    for lidar in result.lidars[1:]:
        assert lidar.uncertainty.undetermined == ()
        assert max(lidar.uncertainty.stddev_translation_m) < 0.005
        assert max(lidar.uncertainty.stddev_rotation_deg) < 0.1


def test_a_bare_floor_leaves_x_y_and_yaw_undetermined_and_only_those() -> None:
    result = floor_only_calibration()
    reference, other = result.lidars
    assert reference.uncertainty.undetermined == ()
    assert other.uncertainty.undetermined == ("x", "y", "yaw")
    # The floor still fixes height, roll and pitch.
    assert other.uncertainty.stddev_translation_m[2] < 0.01
    assert max(other.uncertainty.stddev_rotation_deg[:2]) < 0.1


def test_a_lidar_free_only_together_with_a_group_of_stops_is_undetermined() -> None:
    # A lane driven out and back, each LiDAR seeing one side each way: the objects tie the
    # LiDAR's shift to the return leg's stops and to nothing else, so the LiDAR and those stops
    # slide together. The weak prior of the stops must not hold the LiDAR through them.
    layout = ParameterLayout(n_stops=9, n_lidars=2)
    free = np.zeros(layout.size)
    for stop in range(5, 9):
        free[layout.stop(stop)] = 1.0
    free[layout.lidar(1)] = 1.0
    free /= np.linalg.norm(free)
    information = 1e6 * (np.eye(layout.size) - np.outer(free, free))
    result = _result(
        layout, np.tile(np.eye(4), (2, 1, 1)), information[None], np.zeros((1, layout.size))
    )
    config = ObservabilityConfig(method="formal")
    _, lidar = pose_uncertainties(result, np.eye(4), None, config)
    assert lidar.undetermined == ("x",)
    # With the whole prior on every stop the five poses' priors hold it to 1 m / sqrt(5).
    np.testing.assert_allclose(lidar.stddev_translation_m[0], 1.0 / np.sqrt(5.0), rtol=1e-5)


def test_the_jackknife_is_exact_leave_one_stop_out_on_a_linear_problem() -> None:
    # Residuals linear in the parameters: one Gauss-Newton step from the solution without stop j
    # lands exactly on the solution without stop j, so the jackknife must match brute force.
    rng = np.random.default_rng(3)
    layout = ParameterLayout(n_stops=5, n_lidars=2)
    size = layout.size
    rows = [rng.normal(size=(40, size)) for _ in range(layout.n_stops)]
    targets = [rng.normal(size=40) for _ in range(layout.n_stops)]
    prior = np.full(size, 0.5)

    def solve(stops: list[int]) -> NDArray[np.float64]:
        A = np.vstack([rows[j] for j in stops] + [np.diag(np.sqrt(prior))])
        y = np.concatenate([targets[j] for j in stops] + [np.zeros(size)])
        return np.asarray(np.linalg.lstsq(A, y, rcond=None)[0], dtype=np.float64)

    everything = list(range(layout.n_stops))
    theta = solve(everything)
    H_j = np.stack([A.T @ A for A in rows])
    # Gradients of the data terms at the solution; the prior's (centred on the solution) is 0.
    b_j = np.stack([A.T @ (A @ theta - y) for A, y in zip(rows, targets, strict=True)])
    result = _result(layout, np.tile(np.eye(4), (2, 1, 1)), H_j, b_j)
    # The brute-force solutions keep the prior centred on the full solution, as the jackknife.
    left_out = []
    for j in everything:
        kept = [k for k in everything if k != j]
        A = np.vstack([rows[k] for k in kept] + [np.diag(np.sqrt(prior))])
        y = np.concatenate([targets[k] - rows[k] @ theta for k in kept] + [np.zeros(size)])
        left_out.append(np.linalg.lstsq(A, y, rcond=None)[0])
    offsets = np.array(left_out)
    centred = offsets - offsets.mean(axis=0)
    expected = (len(everything) - 1) / len(everything) * centred.T @ centred
    covariance = jackknife_covariance(result, prior)
    assert covariance is not None
    np.testing.assert_allclose(covariance, expected, rtol=1e-8, atol=1e-12)
    # Leaving out blocks of space is the same computation over other parts: with the stops'
    # parts as the blocks it must agree, and with fewer than three parts there is none.
    as_blocks = dataclasses.replace(result, block_information=H_j, block_gradient=b_j)
    block = block_jackknife_covariance(as_blocks, prior)
    assert block is not None
    np.testing.assert_allclose(block, expected, rtol=1e-8, atol=1e-12)
    two = dataclasses.replace(result, block_information=H_j[:2], block_gradient=b_j[:2])
    assert block_jackknife_covariance(two, prior) is None


def test_reported_stddev_come_from_the_jackknife_never_below_the_formal_ones() -> None:
    problem, _ = box_problem()
    results = [
        calibrate(problem, PipelineConfig(observability=ObservabilityConfig(method=method)))
        for method in ("formal", "jackknife")
    ]
    wider = 0
    for formal, measured in zip(results[0].lidars, results[1].lidars, strict=True):
        assert np.all(
            measured.uncertainty.stddev_translation_m >= formal.uncertainty.stddev_translation_m
        )
        assert np.all(
            measured.uncertainty.stddev_rotation_deg >= formal.uncertainty.stddev_rotation_deg
        )
        wider += int(
            np.any(
                measured.uncertainty.stddev_translation_m > formal.uncertainty.stddev_translation_m
            )
        )
        assert measured.uncertainty.undetermined == formal.uncertainty.undetermined
    # The residuals of a surface patch are correlated: the data's own spread is wider.
    assert wider == len(results[0].lidars) - 1


def test_an_estimated_range_bias_only_ever_widens_the_reported_stddev() -> None:
    result = box_calibration()
    problem, _ = box_problem()
    estimated = calibrate(
        problem, PipelineConfig(observability=ObservabilityConfig(range_bias="estimated"))
    )
    for plain, wider in zip(result.lidars[1:], estimated.lidars[1:], strict=True):
        assert np.all(
            wider.uncertainty.stddev_translation_m >= plain.uncertainty.stddev_translation_m
        )
        assert np.all(
            wider.uncertainty.stddev_rotation_deg >= plain.uncertainty.stddev_rotation_deg
        )
        # On this recording the common-mode estimate is far off (see ObservabilityConfig).
        assert max(wider.uncertainty.stddev_translation_m) > max(
            plain.uncertainty.stddev_translation_m
        )


def test_another_solution_the_data_fit_alike_widens_the_stddev_to_reach_it() -> None:
    layout = ParameterLayout(n_stops=3, n_lidars=2)
    size = layout.size
    T_ref_lidar = np.stack([np.eye(4), make_transform(np.eye(3), [1.0, 0.0, 0.0])])
    result = _result(layout, T_ref_lidar, np.eye(size)[None] * 1e8, np.zeros((1, size)))
    # The other solution: LiDAR 1 turned 2 deg about its own vertical and 0.3 m to the left.
    other = T_ref_lidar.copy()
    other[1] = make_transform(Rotation.from_euler("z", 2.0, degrees=True).as_matrix(), [1, 0.3, 0])
    config = ObservabilityConfig(method="formal")
    alone = pose_uncertainties(result, np.eye(4), None, config)[1]
    both = pose_uncertainties(result, np.eye(4), None, config, alternative_T_ref_lidar=other)[1]
    assert max(alone.stddev_translation_m) < 1e-3 and max(alone.stddev_rotation_deg) < 0.01
    np.testing.assert_allclose(both.stddev_translation_m, [0.0, 0.3, 0.0], atol=1e-3)
    np.testing.assert_allclose(both.stddev_rotation_deg, [0.0, 0.0, 2.0], atol=0.01)
    assert both.undetermined == alone.undetermined == ()
