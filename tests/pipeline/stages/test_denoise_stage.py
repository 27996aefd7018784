import dataclasses

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.calibrate import prepare
from pipeline.config import PipelineConfig
from pipeline.denoise import DenoiseConfig
from pipeline.geometry import Plane
from pipeline.problem import CalibrationProblem, ScanPattern
from pipeline.stages import denoise_stage
from pipeline.stages.denoise_stage import denoise_above_floor
from pipeline.stages.runner import Listeners, StageOutcome
from pipeline.stages.setup import initial_state
from tests.pipeline.calibration_data import box_calibration, box_problem
from tests.pipeline.denoise.clouds import AXIS_ON_FLOOR, FLOOR_PLANE, floor_in_lidar_frame


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


def stage_1(problem: CalibrationProblem, config: PipelineConfig) -> StageOutcome:
    """Stage 1 on `problem` as the pipeline's first stage."""
    return denoise_stage.run(initial_state(problem, config.frames), config, Listeners())


def test_stage_1_filters_every_non_repetitive_lidar_by_default() -> None:
    denoise = box_calibration().stages["denoise"].details
    assert denoise["enabled"] is True and denoise["filtered_frames"] == "lidar_front,lidar_rear"
    assert int(denoise["judged_points"]) > 0


def test_stage_1_keeps_masks_and_copies_a_filtered_cloud_only_when_asked() -> None:
    problem, _ = box_problem()
    prepared = prepare(problem, PipelineConfig(denoise=DenoiseConfig(density_ratio=1.8)))
    stop = problem.stops[0]
    assert prepared.clouds_in_lidar[0][0] is stop.clouds["lidar_front"]  # no copy of the recording
    assert prepared.kept is not None and prepared.floors_in_lidar is not None
    keep = prepared.kept[0][0]
    assert keep is not None and 0 < np.count_nonzero(~keep) < 0.1 * len(keep)
    cloud, floor = prepared.filtered(0, 0)
    np.testing.assert_array_equal(cloud, stop.clouds["lidar_front"][keep])
    recorded_floor = prepared.floors_in_lidar[0][0]
    assert floor is not None and recorded_floor is not None and floor[1].shape == (len(cloud),)
    assert np.count_nonzero(floor[1]) == np.count_nonzero(recorded_floor[1])


def test_stage_1_leaves_repetitive_scans_alone() -> None:
    problem, _ = box_problem()
    spinning_rear = spinning(problem, "lidar_rear")
    prepared = prepare(spinning_rear, PipelineConfig())
    assert prepared.filtered_frames == ("lidar_front",)
    assert prepared.kept is not None and prepared.kept[1] == (None,) * len(problem.stops)
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
    assert stage_1(problem, off).message == "disabled"


def test_stage_1_filters_spinning_lidars_when_the_config_names_their_pattern() -> None:
    problem = spinning(box_problem()[0], "lidar_rear")
    config = PipelineConfig.model_validate(
        {"denoise": {"filtered_patterns": ["non_repetitive", "repetitive"]}}
    )
    prepared = prepare(problem, config)
    assert prepared.filtered_frames == ("lidar_front", "lidar_rear")
    assert prepared.kept is not None and any(keep is not None for keep in prepared.kept[1])
    only_spinning = PipelineConfig.model_validate(
        {"denoise": {"filtered_patterns": ["repetitive"]}}
    )
    assert prepare(problem, only_spinning).filtered_frames == ("lidar_rear",)
    assert stage_1(problem, only_spinning).message.endswith(
        "lidar_front not filtered (non-repetitive scans, not in denoise.filtered_patterns)"
    )
    with pytest.raises(ValidationError, match="name that LiDAR's pattern"):
        PipelineConfig.model_validate({"denoise": {"filtered_patterns": ["unknown"]}})


def test_stage_1_names_the_lidars_it_left_alone() -> None:
    outcome = stage_1(spinning(box_problem()[0]), PipelineConfig())
    assert outcome.message == "lidar_front, lidar_rear not filtered (repetitive scans)"
    assert outcome.details["filtered_frames"] == ""


def test_stage_1_leaves_a_lidar_of_unknown_pattern_alone_and_says_so() -> None:
    problem = spinning(
        spinning(box_problem()[0], "lidar_front"), "lidar_rear", pattern=ScanPattern.UNKNOWN
    )
    assert prepare(problem, PipelineConfig()).filtered_frames == ()
    assert stage_1(problem, PipelineConfig()).message == (
        "lidar_front not filtered (repetitive scans); "
        "lidar_rear not filtered (scan pattern unknown)"
    )


def test_stage_1_judges_only_what_stands_above_the_floor() -> None:
    config = PipelineConfig(denoise=DenoiseConfig(density_ratio=1.8))
    outcome = stage_1(box_problem()[0], config)
    denoise = outcome.details
    assert denoise["enabled"] is True and denoise["method"] == "pattern"
    judged, removed = int(denoise["judged_points"]), int(denoise["removed_points"])
    # The objects and what trails behind them: a small share of every cloud, of which a few
    # per cent are bleeding points.
    assert 0 < removed < judged < 0.3 * int(denoise["input_points"])
    assert outcome.message == f"removed {removed} of the {judged} points above the floor"
    # Per LiDAR too: what each filtered frame had judged and removed adds up to the totals.
    frames = str(denoise["filtered_frames"]).split(",")
    assert sum(int(denoise[f"judged_points.{f}"]) for f in frames) == judged
    assert sum(int(denoise[f"removed_points.{f}"]) for f in frames) == removed
    # The floors' time is segmentation's: taken off this stage's wall time.
    floor_seconds = outcome.state.floor_seconds
    assert floor_seconds > 0 and outcome.credited_seconds == -floor_seconds


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
