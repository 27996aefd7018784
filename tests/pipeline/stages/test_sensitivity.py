import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.config import PipelineConfig
from pipeline.geometry import exp_se3
from pipeline.observability import (
    ObservabilityConfig,
    SurfaceShift,
    pose_uncertainties,
    shift_chance_covariance,
)
from pipeline.optimisation import ParameterLayout
from pipeline.segmentation import SegmentationConfig, SurfaceModel
from pipeline.stages import joint_optimise, sensitivity
from pipeline.stages.runner import Listeners
from pipeline.stages.segment import segment_all
from pipeline.stages.state import CalibrationState
from pipeline.transforms import from_xyz_rpy
from tests.pipeline.stages.test_global_align import _after_stage_3


def _optimised(surface_model: SurfaceModel | None = None) -> CalibrationState:
    return joint_optimise.run(_after_stage_3(surface_model), PipelineConfig(), Listeners()).state


def test_twist_between_undoes_a_step_on_the_left() -> None:
    T = from_xyz_rpy([0.4, -0.2, 0.9], np.radians([3.0, 30.0, -170.0]))
    xi = np.array([0.003, -0.001, 0.002, 0.001, -0.002, 0.0005])
    np.testing.assert_allclose(sensitivity.twist_between(T, exp_se3(xi) @ T), xi, atol=1e-12)


def test_the_shift_vector_holds_each_moved_pose_in_its_own_columns() -> None:
    layout = ParameterLayout(n_stops=3, n_lidars=2)
    stops, lidars = np.stack([np.eye(4)] * 3), np.stack([np.eye(4)] * 2)
    step = np.arange(1.0, 7.0) * 1e-3
    moved_stops, moved_lidars = stops.copy(), lidars.copy()
    moved_stops[2] = exp_se3(step) @ stops[2]
    moved_lidars[1] = exp_se3(-step) @ lidars[1]
    shift = sensitivity.shift_vector(layout, stops, lidars, moved_stops, moved_lidars)
    expected = np.zeros(layout.size)
    expected[layout.stop(2) : layout.stop(2) + 6] = step
    expected[layout.lidar(1) : layout.lidar(1) + 6] = -step
    np.testing.assert_allclose(shift, expected, atol=1e-12)


def test_left_out_nothing_is_measured() -> None:
    state = _after_stage_3()
    off = PipelineConfig(observability=ObservabilityConfig(surface_sensitivity_model=None))
    outcome = sensitivity.run(state, off, Listeners())
    assert outcome.state is state and outcome.state.surface_shift is None
    assert outcome.details == {"enabled": False}


def test_on_it_measures_a_shift_that_only_widens_the_reported_stddev() -> None:
    # The quadric's surfaces, as the option was measured with (its passes on the beam quadric's
    # move this sparse fixture's rear LiDAR 7.5 mm).
    state = _optimised("quadric")
    config = PipelineConfig(
        segmentation=SegmentationConfig(surface_model="quadric"),
        observability=ObservabilityConfig(
            surface_sensitivity_passes=4, surface_sensitivity_model=None
        ),
    )
    heard: list[tuple[int, int]] = []
    outcome = sensitivity.run(state, config, Listeners(on_iteration=lambda *a: heard.append(a)))
    shift = outcome.state.surface_shift
    optimised = state.optimised
    assert shift is not None and optimised is not None
    assert shift.shift.shape == (optimised.layout.size,) and np.all(np.isfinite(shift.shift))
    assert shift.chance is not None and shift.chance.shape == (optimised.layout.size,) * 2
    # The poses stay stage 4's; its re-run is not progress (no bar goes back).
    np.testing.assert_array_equal(outcome.state.T_ref_lidar, state.T_ref_lidar)
    assert heard == []
    frame = state.lidars[1].frame
    moved = outcome.details[f"shift_m:{frame}"]
    assert isinstance(moved, float) and 0.0 < moved < 0.005  # clean boxes: a small shift
    assert outcome.details["surface_passes"] == 4
    plain, wider = (
        pose_uncertainties(optimised, state.T_base_ref_initial, None, config.observability, s)
        for s in (None, shift)
    )
    for before, after in zip(plain[1:], wider[1:], strict=True):
        assert np.all(after.stddev_translation_m >= before.stddev_translation_m)
        assert np.all(after.stddev_rotation_deg >= before.stddev_rotation_deg)
    # A pure translation of one LiDAR that chance cannot give widens its 1-sigma by at least
    # that length; one as large as its chance spread, not at all.
    translation = np.zeros_like(shift.shift)
    col = optimised.layout.lidar(1)
    translation[col : col + 3] = [0.004, 0.0, 0.0]
    chance = np.zeros((len(translation),) * 2)
    chance[col : col + 6, col : col + 6] = np.diag([0.005**2] * 6)
    shifted, by_chance = (
        pose_uncertainties(
            optimised,
            state.T_base_ref_initial,
            None,
            config.observability,
            SurfaceShift(translation, spread),
        )
        for spread in (None, chance)
    )
    assert np.linalg.norm(shifted[1].stddev_translation_m) >= 0.004 - 1e-9
    np.testing.assert_allclose(by_chance[1].stddev_translation_m, plain[1].stddev_translation_m)


def test_the_same_clouds_give_a_shift_no_spread() -> None:
    optimised = _optimised().optimised
    assert optimised is not None
    chance = shift_chance_covariance(optimised, optimised, ObservabilityConfig())
    assert chance is not None
    np.testing.assert_array_equal(chance, np.zeros_like(chance))


def test_another_surface_model_is_measured_as_a_change_of_the_surfaces() -> None:
    config = PipelineConfig(observability=ObservabilityConfig(surface_sensitivity_model="quadric"))
    assert sensitivity.surface_change(config) == {"surface_model": "quadric"}
    both = PipelineConfig(
        observability=ObservabilityConfig(
            surface_sensitivity_passes=2, surface_sensitivity_model="plane"
        )
    )
    assert sensitivity.surface_change(both) == {"surface_passes": 2, "surface_model": "plane"}
    # On by default: the beam quadric's surfaces against the quadric's.
    assert sensitivity.surface_change(PipelineConfig()) == {"surface_model": "quadric"}
    off = ObservabilityConfig(surface_sensitivity_model=None)
    assert sensitivity.surface_change(PipelineConfig(observability=off)) == {}
    alternative = ObservabilityConfig(surface_sensitivity_model="alternative")
    pairs: tuple[tuple[SurfaceModel, SurfaceModel], ...] = (
        ("beam_quadric", "quadric"),
        ("beam_fit", "quadric"),
        ("quadric", "beam_quadric"),
        ("plane", "beam_quadric"),
    )
    for own, other in pairs:
        pair = PipelineConfig(
            segmentation=SegmentationConfig(surface_model=own), observability=alternative
        )
        assert sensitivity.surface_change(pair) == {"surface_model": other}
    state = _optimised()
    outcome = sensitivity.run(state, config, Listeners())
    shift = outcome.state.surface_shift
    assert shift is not None and np.all(np.isfinite(shift.shift))
    assert outcome.details["surface_model"] == "quadric"
    assert "re-fitted (the quadric model)" in outcome.message
    # The rear LiDAR moves: the two models settle the points differently, by millimetres.
    moved = outcome.details[f"shift_m:{state.lidars[1].frame}"]
    assert isinstance(moved, float) and 0.0 < moved < 0.02


def test_the_calibrations_own_surface_model_is_refused_as_its_alternative() -> None:
    with pytest.raises(ValidationError, match="would measure nothing"):
        PipelineConfig(
            segmentation=SegmentationConfig(surface_model="quadric"),
            observability=ObservabilityConfig(surface_sensitivity_model="quadric"),
        )


def test_the_quadric_alternative_comes_from_the_beam_quadrics_own_fit() -> None:
    state = _after_stage_3()
    config = PipelineConfig()
    other = config.model_copy(
        update={"segmentation": config.segmentation.model_copy(update={"surface_model": "quadric"})}
    )
    shared = sensitivity.refitted_segments(state, config, {"surface_model": "quadric"})
    again = segment_all(state, other)
    assert state.segments is not None
    for shared_row, again_row, own_row in zip(shared, again, state.segments, strict=True):
        for kept, fitted, own in zip(shared_row, again_row, own_row, strict=True):
            np.testing.assert_array_equal(kept.object_points, fitted.object_points)
            np.testing.assert_array_equal(kept.object_normals, fitted.object_normals)
            assert len(own.object_points) == 0 or not np.array_equal(
                own.object_points, kept.object_points
            )
