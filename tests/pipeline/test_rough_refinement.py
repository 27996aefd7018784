import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import BadInputError
from pipeline.rough_refinement import RoughRefinementConfig, floor_noise, refine_with_floor
from tests.pipeline.calibration_data import (
    box_prepared,
    box_problem,
    true_T_G_ref,
    true_T_ref_lidar,
)


def _floor_errors(
    estimate: np.ndarray, truth: np.ndarray, up: np.ndarray
) -> tuple[float, float, float, float]:
    """Tilt (deg) and height (m) errors across the floor, and yaw (deg) and horizontal (m)
    errors along it, of a pose (4, 4) whose parent frame has the floor normal `up`."""
    delta = estimate @ np.linalg.inv(truth)
    rotation = Rotation.from_matrix(delta[:3, :3]).as_rotvec()
    shift = estimate[:3, 3] - truth[:3, 3]
    tilt = np.degrees(np.linalg.norm(rotation - (rotation @ up) * up))
    yaw = np.degrees(abs(rotation @ up))
    return tilt, abs(shift @ up), yaw, float(np.linalg.norm(shift - (shift @ up) * up))


def test_roll_pitch_and_height_of_every_lidar_and_stop_come_from_the_floor() -> None:
    _, truth = box_problem()
    prepared, segments = box_prepared()
    frames = tuple(lidar.frame for lidar in prepared.lidars)
    T_ref_lidar_true = true_T_ref_lidar(truth, frames)
    T_G_ref_true = true_T_G_ref(truth, frames[0])
    planes = [[s.floor for s in row] for row in segments]
    result = refine_with_floor(
        planes, prepared.T_G_ref, prepared.T_ref_lidar, RoughRefinementConfig()
    )
    assert result.converged and result.observations == 32
    # The floor in the reference frame, from the truth.
    T_base_ref = {x.frame: x.T_base_lidar_true for x in truth.lidars}[frames[0]]
    up_ref = T_base_ref[:3, :3].T @ [0.0, 0.0, 1.0]
    before = _floor_errors(prepared.T_ref_lidar[1], T_ref_lidar_true[1], up_ref)
    after = _floor_errors(result.T_ref_lidar[1], T_ref_lidar_true[1], up_ref)
    assert before[0] > 0.5 or before[1] > 0.01  # the start was off across the floor...
    assert after[0] < 0.05 and after[1] < 0.003  # ...and the floor fixed it
    # x, y and yaw are left for the objects: unchanged up to the tilt's lever arm.
    assert abs(after[2] - before[2]) < 0.2
    for j in range(1, len(T_G_ref_true)):
        tilt, height, _, _ = _floor_errors(result.T_G_ref[j], T_G_ref_true[j], up_ref)
        assert tilt < 0.05 and height < 0.003
    assert result.residual_final.tilt_deg < 0.05
    assert result.residual_final.offset_m < 0.002
    # 32 floors, 16 stops and 2 LiDARs: 96 rows against 48 parameters leave the floors' spread.
    assert result.noise is not None
    assert 0 < result.noise.tilt_deg < 0.05 and 0 < result.noise.offset_m < 0.002


def test_floor_noise_is_the_residuals_robust_spread_corrected_for_the_fit() -> None:
    """Residuals of known spread come back as that spread, inflated by sqrt(rows / (rows - P))
    for what the fit absorbed; a box top taken for the floor (a gross residual) does not move
    it; no redundancy, or no spread at all, measures nothing."""
    rng = np.random.default_rng(3)
    k = 4000
    tilt = rng.normal(0.0, np.radians(0.01), (k, 2))
    offset = rng.normal(0.0, 0.0004, k)
    offset[:40] = 0.3
    noise = floor_noise(tilt, offset, parameters=3 * k // 2)
    assert noise is not None
    inflation = np.sqrt(2.0)  # 3k rows, 1.5k parameters
    assert noise.tilt_deg == pytest.approx(0.01 * inflation, rel=0.05)
    assert noise.offset_m == pytest.approx(0.0004 * inflation, rel=0.05)
    assert floor_noise(tilt[:10], offset[:10], parameters=30) is None
    assert floor_noise(np.zeros((10, 2)), np.zeros(10), parameters=3) is None


def test_no_floor_anywhere_is_bad_input() -> None:
    prepared, _ = box_prepared()
    planes = [[None] * len(prepared.T_G_ref) for _ in prepared.lidars]
    with pytest.raises(BadInputError, match="no LiDAR saw a floor plane"):
        refine_with_floor(planes, prepared.T_G_ref, prepared.T_ref_lidar, RoughRefinementConfig())
