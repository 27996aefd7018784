import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.calibrate import STAGES, calibrate, denoise_above_floor, prepare
from pipeline.config import PipelineConfig
from pipeline.denoise import DenoiseConfig
from pipeline.errors import BadInputError
from pipeline.problem import CalibrationProblem, ScanPattern
from pipeline.segmentation import Plane
from pipeline.transforms import invert, pose_difference
from tests.pipeline.calibration_data import (
    box_calibration,
    box_problem,
    floor_only_calibration,
)
from tests.pipeline.denoise.clouds import AXIS_ON_FLOOR, FLOOR_PLANE, floor_in_lidar_frame


def test_calibration_recovers_the_extrinsics_and_passes() -> None:
    problem, truth = box_problem()
    result = box_calibration()
    true = {lidar.frame: lidar.T_base_lidar_true for lidar in truth.lidars}
    reference = result.lidars[0]
    assert reference.is_reference and reference.frame == "lidar_front"
    np.testing.assert_array_equal(
        reference.T_base_lidar_calibrated, problem.lidar("lidar_front").T_base_lidar
    )
    for lidar in result.lidars[1:]:
        relative = invert(reference.T_base_lidar_calibrated) @ lidar.T_base_lidar_calibrated
        initial = invert(reference.T_base_lidar_initial) @ lidar.T_base_lidar_initial
        true_relative = invert(true[reference.frame]) @ true[lidar.frame]
        assert pose_difference(true_relative, initial)[0] > 0.05
        translation, rotation = pose_difference(true_relative, relative)
        assert translation < 0.01 and rotation < 0.1
    assert result.passed, [c.name for c in result.verdict.failed]
    assert result.metric_error_final < 0.5 * result.metric_error_initial
    assert tuple(result.stages) == STAGES
    assert all(stage.seconds >= 0 for stage in result.stages.values())
    assert result.T_odom_base.shape == (len(problem.stops), 4, 4)


def test_floor_in_the_base_frame_fixes_the_reference_height_roll_and_pitch() -> None:
    problem, truth = box_problem()
    config = PipelineConfig.model_validate({"frames": {"base_height_above_floor_m": 0.0}})
    result = calibrate(problem, config)
    true = truth.lidars[0].T_base_lidar_true
    reference = result.lidars[0]

    def roll_pitch(T: np.ndarray) -> np.ndarray:
        return np.asarray(np.degrees(Rotation.from_matrix(T[:3, :3]).as_euler("xyz")[:2]))

    initial = reference.T_base_lidar_initial
    assert (
        abs(initial[2, 3] - true[2, 3]) > 0.01
        or np.abs(roll_pitch(initial) - roll_pitch(true)).max() > 0.5
    )
    assert abs(reference.T_base_lidar_calibrated[2, 3] - true[2, 3]) < 0.005
    assert np.abs(roll_pitch(reference.T_base_lidar_calibrated) - roll_pitch(true)).max() < 0.1


def test_a_bare_floor_fails_the_verdict_naming_x_y_and_yaw() -> None:
    result = floor_only_calibration()
    assert not result.passed
    failed = {check.name: check for check in result.verdict.failed}
    check = failed["determined:lidar_rear"]
    assert check.dofs == ("x", "y", "yaw")
    assert "x, y, yaw" in check.detail


def test_unknown_reference_and_single_stop_are_bad_input() -> None:
    problem, _ = box_problem()
    config = PipelineConfig.model_validate({"frames": {"reference_frame": "lidar_top"}})
    with pytest.raises(BadInputError, match="reference LiDAR 'lidar_top' is not in the recording"):
        calibrate(problem, config)
    with pytest.raises(BadInputError, match="at least two stops"):
        calibrate(dataclasses.replace(problem, stops=problem.stops[:1]))


def test_stage_1_filters_every_non_repetitive_lidar_by_default() -> None:
    denoise = box_calibration().stages["denoise"].details
    assert denoise["enabled"] is True and denoise["filtered_frames"] == "lidar_front,lidar_rear"
    assert int(denoise["judged_points"]) > 0


def test_stage_1_keeps_masks_and_copies_a_filtered_cloud_only_when_asked() -> None:
    problem, _ = box_problem()
    prepared = prepare(problem, PipelineConfig(denoise=DenoiseConfig(density_ratio=1.8)))
    stop = problem.stops[0]
    assert prepared.clouds[0][0] is stop.clouds["lidar_front"]  # no copy of the recording
    keep = prepared.kept[0][0]
    assert keep is not None and 0 < np.count_nonzero(~keep) < 0.1 * len(keep)
    cloud, floor = prepared.filtered(0, 0)
    np.testing.assert_array_equal(cloud, stop.clouds["lidar_front"][keep])
    recorded_floor = prepared.floors[0][0]
    assert floor is not None and recorded_floor is not None and floor[1].shape == (len(cloud),)
    assert np.count_nonzero(floor[1]) == np.count_nonzero(recorded_floor[1])


def spinning(
    problem: CalibrationProblem, *frames: str, pattern: ScanPattern = ScanPattern.REPETITIVE
) -> CalibrationProblem:
    """`problem` with the LiDARs `frames` (all when none given) tagged as spinning ones (or as
    `pattern`)."""
    return dataclasses.replace(
        problem,
        lidars=tuple(
            dataclasses.replace(lidar, scan_pattern=pattern)
            if not frames or lidar.frame in frames
            else lidar
            for lidar in problem.lidars
        ),
    )


def test_stage_1_leaves_repetitive_scans_alone() -> None:
    problem, _ = box_problem()
    spinning_rear = spinning(problem, "lidar_rear")
    prepared = prepare(spinning_rear, PipelineConfig())
    assert prepared.filtered_frames == ("lidar_front",)
    assert prepared.kept[1] == (None,) * len(problem.stops)
    # The config overrides what the recording says, either way.
    told = PipelineConfig.model_validate(
        {
            "denoise": {
                "scan_patterns": {"lidar_rear": "non_repetitive", "lidar_front": "repetitive"}
            }
        }
    )
    assert prepare(spinning_rear, told).filtered_frames == ("lidar_rear",)
    off = PipelineConfig.model_validate({"denoise": {"enabled": False}})
    assert prepare(problem, off).filtered_frames == ()


def test_progress_names_the_lidars_stage_1_left_alone() -> None:
    said: dict[str, str] = {}

    def progress(stage: str, seconds: float, message: str) -> None:
        said[stage] = message

    result = calibrate(spinning(box_problem()[0]), progress=progress)
    assert said["denoise"] == "lidar_front, lidar_rear not filtered (repetitive scans)"
    assert result.stages["denoise"].details["filtered_frames"] == ""


def test_stage_1_leaves_a_lidar_of_unknown_pattern_alone_and_says_so() -> None:
    problem = spinning(
        spinning(box_problem()[0], "lidar_front"), "lidar_rear", pattern=ScanPattern.UNKNOWN
    )
    assert prepare(problem, PipelineConfig()).filtered_frames == ()
    said: dict[str, str] = {}
    calibrate(problem, progress=lambda stage, _, message: said.__setitem__(stage, message))
    assert said["denoise"] == (
        "lidar_front not filtered (repetitive scans); "
        "lidar_rear not filtered (scan pattern unknown)"
    )


def test_stage_1_judges_only_what_stands_above_the_floor() -> None:
    config = PipelineConfig(denoise=DenoiseConfig(density_ratio=1.8))
    result = calibrate(box_problem()[0], config)
    denoise = result.stages["denoise"].details
    assert denoise["enabled"] is True and denoise["method"] == "pattern"
    judged, removed = int(denoise["judged_points"]), int(denoise["removed_points"])
    # The objects and what trails behind them: a small share of every cloud, of which a few
    # per cent are bleeding points.
    assert 0 < removed < judged < 0.3 * int(denoise["input_points"])
    # Per LiDAR too: what each filtered frame had judged and removed adds up to the totals.
    frames = str(denoise["filtered_frames"]).split(",")
    assert sum(int(denoise[f"judged_points.{f}"]) for f in frames) == judged
    assert sum(int(denoise[f"removed_points.{f}"]) for f in frames) == removed


def test_stage_1_takes_each_lidars_optical_axis_from_the_config() -> None:
    cloud = floor_in_lidar_frame(5000)
    floor = Plane(normal=FLOOR_PLANE[:3], offset=float(FLOOR_PLANE[3]))
    config = PipelineConfig.model_validate(
        {"denoise": {"method": "proposed", "optical_axes": {"lidar_side": (1.0, 0.2, 0.0)}}}
    )
    default = denoise_above_floor(cloud, floor, config, "lidar_front").observation_centre
    side = denoise_above_floor(cloud, floor, config, "lidar_side").observation_centre
    assert default is not None and side is not None
    np.testing.assert_allclose(default, AXIS_ON_FLOOR, atol=1e-9)
    # On the floor, along the configured axis.
    assert abs(FLOOR_PLANE[:3] @ side + FLOOR_PLANE[3]) < 1e-9
    axis = np.array([1.0, 0.2, 0.0])
    np.testing.assert_allclose(side / np.linalg.norm(side), axis / np.linalg.norm(axis))


def test_each_optimisation_iteration_is_reported() -> None:
    seen: list[tuple[int, int]] = []
    result = calibrate(box_problem()[0], on_iteration=lambda k, n: seen.append((k, n)))
    iterations = result.stages["optimisation"].details["iterations"]
    assert isinstance(iterations, int) and iterations > 1
    assert seen == [
        (k, PipelineConfig().optimisation.max_iterations) for k in range(1, iterations + 1)
    ]
