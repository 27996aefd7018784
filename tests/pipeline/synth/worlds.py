"""Small, fast versions of the named world scenarios for the tests of the world options."""

from __future__ import annotations

from pipeline.problem import CalibrationProblem
from pipeline.synth import Truth, get_scenario, simulate_problem
from pipeline.synth.motion import ArcMotion
from pipeline.synth.scenarios import ScenarioSpec


def short(name: str, stops: int = 3, dwell_s: float = 0.6) -> ScenarioSpec:
    """Scenario `name` with a short routine: `stops` stops of `dwell_s`, 90 deg apart."""
    motion = ArcMotion(stops=stops, step_deg=90.0, dwell_s=dwell_s, move_s=0.3)
    return get_scenario(name).model_copy(update={"motion": motion})


def small_problem(
    name: str, seed: int = 0, stops: int = 3, rate_scale: float = 0.05, dwell_s: float = 0.6
) -> tuple[CalibrationProblem, Truth]:
    return simulate_problem(short(name, stops, dwell_s), seed=seed, rate_scale=rate_scale)
