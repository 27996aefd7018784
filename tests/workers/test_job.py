"""The pipeline config of a run: the upload's config with the verdict's limits from the robot's
tolerance profile; an upload cannot set (loosen) its own verdict."""

from __future__ import annotations

import itertools

import pytest

from pipeline.config import PipelineConfig
from pipeline.errors import ConfigError
from workers.job import pipeline_config_for


def test_the_profile_sets_the_verdict_and_the_upload_the_rest() -> None:
    limits = {
        "max_metric_error_m": 0.02,
        "max_rotation_stddev_deg": 0.3,
        "max_translation_drift_m": 0.01,
    }
    config = pipeline_config_for({"frames": {"reference_frame": "lidar_rear"}}, limits)
    assert config.frames.reference_frame == "lidar_rear"
    assert config.verdict.max_metric_error_m == 0.02
    assert config.verdict.max_rotation_stddev_deg == 0.3
    default = PipelineConfig().verdict
    assert config.verdict.max_translation_stddev_m == default.max_translation_stddev_m


def test_an_upload_cannot_set_its_verdict() -> None:
    with pytest.raises(ConfigError, match="tolerance profile"):
        pipeline_config_for({"verdict": {"max_metric_error_m": 10.0}}, {})


def test_an_unknown_setting_is_a_config_error_naming_it() -> None:
    with pytest.raises(ConfigError, match=r"optimisation\.max_iteration"):
        pipeline_config_for({"optimisation": {"max_iteration": 5}}, {})


def test_optimisation_progress_moves_at_every_iteration_and_stays_in_its_stage() -> None:
    from workers.job import _STAGE_PROGRESS, optimisation_progress

    values = [optimisation_progress(k, 200) for k in range(0, 201)]
    assert values[0] == _STAGE_PROGRESS["optimisation"]
    assert all(b > a for a, b in itertools.pairwise(values))
    assert values[-1] == _STAGE_PROGRESS["metric"]
    # A typical run converges in tens of iterations: by then most of the stage's share is shown.
    assert values[30] > _STAGE_PROGRESS["optimisation"] + 0.8 * (
        _STAGE_PROGRESS["metric"] - _STAGE_PROGRESS["optimisation"]
    )
