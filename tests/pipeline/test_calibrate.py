import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pipeline.calibrate
from pipeline.calibrate import STAGES, calibrate
from pipeline.config import PipelineConfig
from pipeline.errors import BadInputError
from pipeline.stages.runner import Listeners, Stage, StageOutcome
from pipeline.stages.sequence import STAGE_SEQUENCE
from pipeline.stages.state import CalibrationState
from pipeline.transforms import invert, pose_difference
from tests.pipeline.calibration_data import (
    box_calibration,
    box_problem,
    dense_box_calibration,
    dense_box_problem,
    floor_only_calibration,
)


def test_calibration_recovers_the_extrinsics_and_passes() -> None:
    problem, truth = dense_box_problem()
    result = dense_box_calibration()
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


def test_each_optimisation_iteration_is_reported() -> None:
    seen: list[tuple[int, int]] = []
    result = calibrate(box_problem()[0], on_iteration=lambda k, n: seen.append((k, n)))
    iterations = result.stages["optimisation"].details["iterations"]
    assert isinstance(iterations, int) and iterations > 1
    assert seen == [
        (k, PipelineConfig().optimisation.max_iterations) for k in range(1, iterations + 1)
    ]


def test_calibrate_runs_the_declared_sequence_and_a_stage_inserted_in_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """One place declares the stages: a stage added there runs in its place, reports once and
    is heard once, like every other."""
    seen: list[CalibrationState] = []

    def look(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
        seen.append(state)
        return StageOutcome(state, {"looked": True}, "looked at the state")

    sequence = (*STAGE_SEQUENCE[:4], Stage("look", look), *STAGE_SEQUENCE[4:])
    monkeypatch.setattr(pipeline.calibrate, "STAGE_SEQUENCE", sequence)
    heard: list[tuple[str, float, str]] = []
    result = calibrate(
        box_problem()[0],
        progress=lambda stage, seconds, message: heard.append((stage, seconds, message)),
    )
    names = (*STAGES[:4], "look", *STAGES[4:])
    assert tuple(result.stages) == names
    assert [stage for stage, _, _ in heard] == list(names)
    assert [seconds for _, seconds, _ in heard] == [
        report.seconds for report in result.stages.values()
    ]
    assert heard[4][2] == "looked at the state"
    assert result.stages["look"].details == {"looked": True}
    # It ran after stage 3 and before stage 4, and changed nothing.
    assert len(seen) == 1 and seen[0].floor_refinement is not None and seen[0].optimised is None
    plain = box_calibration()
    for lidar, plain_lidar in zip(result.lidars, plain.lidars, strict=True):
        np.testing.assert_allclose(
            lidar.T_base_lidar_calibrated,
            plain_lidar.T_base_lidar_calibrated,
            rtol=1e-9,
            atol=1e-12,
        )
    assert result.metric_error_final == pytest.approx(plain.metric_error_final, rel=1e-9)
