import dataclasses

import numpy as np

from pipeline.config import PipelineConfig
from pipeline.optimisation.config import FALLBACK_FLOOR_SIGMA
from pipeline.stages import joint_optimise
from pipeline.stages.runner import Listeners
from pipeline.transforms import pose_difference
from tests.pipeline.calibration_data import box_problem, true_T_ref_lidar
from tests.pipeline.stages.test_global_align import _after_stage_3, _pushed_far


def test_one_start_reports_no_second() -> None:
    outcome = joint_optimise.run(_after_stage_3(), PipelineConfig(), Listeners())
    assert "starts" not in outcome.details
    assert outcome.state.optimised is not None
    assert outcome.state.start_comparison is None


def test_of_two_starts_the_solution_nearer_the_reference_map_is_kept_whichever_comes_first() -> (
    None
):
    near = _after_stage_3()
    far = _pushed_far(near)
    _, truth = box_problem()
    T_true = true_T_ref_lidar(truth, tuple(lidar.frame for lidar in near.lidars))
    config = PipelineConfig()
    for state, second_kept in (
        (dataclasses.replace(near, second_start=(far.T_G_ref, far.T_ref_lidar)), False),
        (dataclasses.replace(far, second_start=(near.T_G_ref, near.T_ref_lidar)), True),
    ):
        outcome = joint_optimise.run(state, config, Listeners())
        details = outcome.details
        assert details["starts"] == 2
        assert details["second_start_kept"] is second_kept
        kept, other = details["metric_error_m"], details["second_start_metric_error_m"]
        assert isinstance(kept, float) and isinstance(other, float)
        assert (other < kept) is second_kept
        translation, _ = pose_difference(outcome.state.T_ref_lidar[1], T_true[1])
        assert translation < 0.01
        optimised = outcome.state.optimised
        assert optimised is not None
        np.testing.assert_array_equal(outcome.state.T_ref_lidar, optimised.T_ref_lidar)
        # Both starts end at the truth: one calibration, which the verdict need not question.
        compared = outcome.state.start_comparison
        assert compared is not None and compared.apart_translation_m < 0.005
        assert details["starts_apart_m"] == compared.apart_translation_m
        assert details["kept_start_nearer_m"] == compared.difference_m


def test_with_two_starts_iterations_are_counted_on_so_progress_never_goes_back() -> None:
    near = _after_stage_3()
    far = _pushed_far(near)
    heard: list[tuple[int, int]] = []
    listeners = Listeners(on_iteration=lambda done, limit: heard.append((done, limit)))
    state = dataclasses.replace(near, second_start=(far.T_G_ref, far.T_ref_lidar))
    outcome = joint_optimise.run(state, PipelineConfig(), listeners)
    done = [d for d, _ in heard]
    assert done == list(range(1, len(done) + 1))
    assert len(done) == outcome.details["iterations_all_starts"]
    assert {limit for _, limit in heard} == {2 * PipelineConfig().optimisation.max_iterations}


def test_the_metric_that_chose_between_two_starts_is_the_one_the_metric_stage_reports() -> None:
    from pipeline.metric import metric_error
    from pipeline.stages import measure

    near = _after_stage_3()
    far = _pushed_far(near)
    state = dataclasses.replace(near, second_start=(far.T_G_ref, far.T_ref_lidar))
    config = PipelineConfig()
    optimised = joint_optimise.run(state, config, Listeners()).state
    assert optimised.metric_final is not None
    measured = measure.run(optimised, config, Listeners()).state
    assert measured.metric_final is optimised.metric_final
    again = metric_error(
        optimised.objects_in_lidar(), optimised.T_G_ref, optimised.T_ref_lidar, config.metric
    )
    assert again.value == optimised.metric_final.value
    single = joint_optimise.run(near, config, Listeners()).state
    assert single.metric_final is None


def test_floor_sigmas_left_to_be_measured_come_from_stage_3s_floor_residuals() -> None:
    """None takes stage 3's measured spread; a value set is kept; without stage 3 the fallback."""
    state = _after_stage_3()
    assert state.floor_refinement is not None and state.floor_refinement.noise is not None
    noise = state.floor_refinement.noise
    measured = PipelineConfig.model_validate(
        {"optimisation": {"floor_normal_sigma_deg": None, "floor_offset_sigma_m": None}}
    )
    options = joint_optimise.stage4_config(state, measured)
    assert options.floor_normal_sigma_deg == noise.tilt_deg
    assert options.floor_offset_sigma_m == noise.offset_m
    fixed = PipelineConfig()
    assert joint_optimise.stage4_config(state, fixed) == fixed.optimisation
    without_stage_3 = dataclasses.replace(state, floor_refinement=None)
    fallback = joint_optimise.stage4_config(without_stage_3, measured)
    assert (fallback.floor_normal_sigma_deg, fallback.floor_offset_sigma_m) == FALLBACK_FLOOR_SIGMA
