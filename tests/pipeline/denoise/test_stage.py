"""`denoise`, the stage the pipeline calls: config, dispatch, result record, defined edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.denoise import (
    DenoiseConfig,
    DenoiseMethod,
    denoise,
    dsor_mask,
    observation_centre,
    pattern_mask,
    proposed_mask,
    sor_mask,
)
from pipeline.errors import BadInputError
from tests.pipeline.denoise.clouds import AXIS, floor_in_lidar_frame, veil


def test_the_config_holds_the_papers_defaults_and_is_frozen() -> None:
    config = DenoiseConfig()
    assert (config.enabled, config.k, config.cs, config.cr) == (True, 20, 0.01, 3.0)
    assert config.method is DenoiseMethod.PATTERN
    with pytest.raises(ValidationError, match="frozen"):
        config.k = 5
    with pytest.raises(ValidationError, match="greater than 0"):
        DenoiseConfig(cr=0.0)
    with pytest.raises(ValidationError, match="Extra inputs"):
        DenoiseConfig(c_r=3.0)  # type: ignore[call-arg]
    assert DenoiseConfig(method="sor").method is DenoiseMethod.SOR  # type: ignore[arg-type]


def test_each_method_gives_the_mask_of_its_function() -> None:
    cloud = np.vstack([floor_in_lidar_frame(8_000), veil(200)])
    centre = observation_centre(cloud, AXIS)
    expected = {
        DenoiseMethod.SOR: sor_mask(cloud),
        DenoiseMethod.DSOR: dsor_mask(cloud),
        DenoiseMethod.PROPOSED: proposed_mask(cloud, centre),
        DenoiseMethod.FLOORED: proposed_mask(cloud, centre, floored=True),
        DenoiseMethod.PATTERN: pattern_mask(cloud),
    }

    for method, keep in expected.items():
        result = denoise(cloud, DenoiseConfig(method=method), optical_axis=AXIS)
        np.testing.assert_array_equal(result.keep, keep)
        assert result.method is method
        assert result.removed_points == int((~keep).sum()) > 0
        assert result.seconds > 0 and result.note is None
        uses_centre = method in (DenoiseMethod.PROPOSED, DenoiseMethod.FLOORED)
        assert (result.observation_centre is not None) == uses_centre


def test_a_given_floor_plane_sets_the_centre() -> None:
    cloud = floor_in_lidar_frame(5_000)
    plane = np.array([0.0, 0.0, 1.0, 0.1])  # z = -0.1: the axis (+x) is parallel to it -> missed
    result = denoise(cloud, DenoiseConfig(method=DenoiseMethod.PROPOSED), AXIS, plane)
    np.testing.assert_array_equal(result.observation_centre, observation_centre(cloud, AXIS, plane))


def test_too_few_points_are_kept_with_a_note() -> None:
    result = denoise(floor_in_lidar_frame(200)[:20], DenoiseConfig(k=20))
    assert result.keep.all() and result.keep.shape == (20,)
    assert result.note == "20 points are too few to judge with k=20; kept all"


def test_a_disabled_stage_keeps_everything_with_a_note() -> None:
    cloud = np.vstack([floor_in_lidar_frame(2_000), veil(200)])
    result = denoise(cloud, DenoiseConfig(enabled=False))
    assert result.keep.all() and result.removed_points == 0
    assert result.note == "stage 1 disabled in the config"


def test_an_empty_cloud_gives_an_empty_mask() -> None:
    result = denoise(np.zeros((0, 3)))
    assert result.keep.shape == (0,) and result.removed_points == 0


@pytest.mark.parametrize("method", list(DenoiseMethod))
def test_a_cloud_at_one_spot_is_kept(method: DenoiseMethod) -> None:
    result = denoise(np.tile([[1.0, 0.2, -0.3]], (100, 1)), DenoiseConfig(method=method))
    assert result.keep.all() and result.note is None


def test_float32_input_is_accepted_and_nan_refused() -> None:
    cloud = floor_in_lidar_frame(2_000)
    np.testing.assert_array_equal(
        denoise(cloud.astype(np.float32)).keep, denoise(cloud.astype(np.float32).astype(float)).keep
    )
    cloud[0, 0] = np.inf
    with pytest.raises(BadInputError, match="NaN or inf coordinates; drop them"):
        denoise(cloud)


@pytest.mark.parametrize("method", list(DenoiseMethod))
def test_only_the_judged_points_can_be_removed(method: DenoiseMethod) -> None:
    floor = floor_in_lidar_frame(20_000)
    sheet = veil(300)
    cloud = np.vstack([floor, sheet])
    judge = np.r_[np.zeros(len(floor), bool), np.ones(len(sheet), bool)]
    config = DenoiseConfig(method=method, population_points=4_000)

    result = denoise(cloud, config, optical_axis=AXIS, judge=judge)

    assert result.keep[: len(floor)].all()
    assert result.judged_points == len(sheet)
    whole = denoise(cloud, config, optical_axis=AXIS).keep[len(floor) :]
    # Statistics from a sample of the cloud instead of every point: the verdicts on the sheet
    # are the same but for a few points near a threshold.
    assert np.count_nonzero(result.keep[len(floor) :] != whole) <= 0.05 * len(sheet)


def test_the_judged_pattern_filter_removes_the_veil_and_keeps_the_floor() -> None:
    floor = floor_in_lidar_frame(20_000)
    sheet = veil(300)
    cloud = np.vstack([floor, sheet])
    judge = np.r_[np.zeros(len(floor), bool), np.ones(len(sheet), bool)]
    result = denoise(cloud, DenoiseConfig(), judge=judge)
    assert np.count_nonzero(~result.keep[len(floor) :]) > 0.5 * len(sheet)
    assert result.keep[: len(floor)].all()


def test_a_judge_mask_of_the_wrong_length_is_refused() -> None:
    cloud = floor_in_lidar_frame(2_000)
    with pytest.raises(BadInputError, match="one entry per point"):
        denoise(cloud, DenoiseConfig(), judge=np.ones(len(cloud) - 1, bool))
