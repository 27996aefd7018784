"""An upload's calibration config (`X-Fleetcal-Config`), checked when it arrives: JSON that both
databases store, and a valid `PipelineConfig`. A bad config is a 422 problem at upload, not a
run that fails later in the worker."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

from pipeline import ConfigError, config_from_mapping
from service.problem_details import InvalidConfig

HEADER = "X-Fleetcal-Config"


class _NonFiniteNumberError(ValueError):
    pass


def _refuse_constant(name: str) -> float:
    raise _NonFiniteNumberError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _NonFiniteNumberError(f"{text} is beyond the range of a float64")
    return value


def verdict_refusal(config: Mapping[str, Any]) -> str | None:
    """Why an upload's config may not be used, when it sets the verdict: a robot must not loosen
    its own tolerances. Checked at upload and again by the worker (`workers.job`), for configs
    stored before this check."""
    if "verdict" not in config:
        return None
    return (
        "sets 'verdict'; a run's tolerances come from the robot's tolerance profile "
        "(PUT /v1/tolerance-profiles/{name}), remove 'verdict'"
    )


def parse_run_config(raw: str | None) -> dict[str, Any] | None:
    """The config as plain data (stored with the run as sent), or `InvalidConfig`."""
    if raw is None:
        return None
    try:
        # NaN and Infinity parse in Python, but PostgreSQL refuses them in JSON.
        value = json.loads(raw, parse_constant=_refuse_constant, parse_float=_finite_float)
    except _NonFiniteNumberError as err:
        raise InvalidConfig(f"{HEADER} holds a number JSON cannot carry: {err}") from err
    except RecursionError as err:
        raise InvalidConfig(
            f"{HEADER} is nested too deeply; a pipeline config is sections of parameters, "
            'e.g. {"frames": {"reference_frame": "lidar_front"}}'
        ) from err
    except ValueError as err:
        raise InvalidConfig(f"{HEADER} is not valid JSON: {err}") from err
    if not isinstance(value, dict):
        raise InvalidConfig(f"{HEADER} must be a JSON object of config sections")
    if (refusal := verdict_refusal(value)) is not None:
        raise InvalidConfig(f"{HEADER} {refusal}")
    try:
        config_from_mapping(value)
    except ConfigError as err:
        raise InvalidConfig(f"{HEADER}: {err}") from err
    return value
