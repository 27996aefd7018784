"""An upload's `X-Fleetcal-Config` is checked when it arrives: JSON both databases store, and a
valid pipeline config without its own verdict."""

from __future__ import annotations

import pytest

from service.problem_details import InvalidConfig
from service.run_config import parse_run_config


def test_a_valid_config_is_kept_as_sent() -> None:
    raw = '{"frames": {"reference_frame": "lidar_front"}, "optimisation": {"max_iterations": 7}}'
    assert parse_run_config(raw) == {
        "frames": {"reference_frame": "lidar_front"},
        "optimisation": {"max_iterations": 7},
    }
    assert parse_run_config(None) is None
    assert parse_run_config("{}") == {}


@pytest.mark.parametrize(
    ("raw", "match"),
    [
        ('{"a": ' + "[" * 5000 + "]" * 5000 + "}", "nested too deeply"),
        ('{"frames": {"base_height_above_floor_m": NaN}}', "NaN is not a JSON number"),
        ('{"frames": {"base_height_above_floor_m": -Infinity}}', "-Infinity is not a JSON number"),
        ('{"frames": {"base_height_above_floor_m": 1e400}}', "1e400 is beyond the range"),
        ("{not json", "not valid JSON"),
        ("[1, 2]", "must be a JSON object"),
        ('"frames"', "must be a JSON object"),
        ('{"verdict": {"max_metric_error_m": 100}}', "tolerance profile"),
        ('{"optimisation": {"iterations": 5}}', "optimisation.iterations"),
        ('{"optimisation": {"max_iterations": 0}}', "max_iterations"),
        ('{"frames": {"reference_frame": 3}}', "reference_frame"),
        ('{"unknown_section": {}}', "unknown_section"),
    ],
    ids=[
        "deep",
        "nan",
        "infinity",
        "float-overflow",
        "not-json",
        "array",
        "string",
        "verdict",
        "unknown-key",
        "out-of-range",
        "wrong-type",
        "unknown-section",
    ],
)
def test_a_bad_config_is_refused_with_its_reason(raw: str, match: str) -> None:
    with pytest.raises(InvalidConfig, match=match):
        parse_run_config(raw)
