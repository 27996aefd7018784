"""The one loop that runs a sequence of stages: it times each, keeps its `StageReport` and tells
the listeners, so no stage does any of that itself."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from pipeline.config import PipelineConfig
from pipeline.stages.state import CalibrationState, Detail, StageReport

Progress = Callable[[str, float, str], None]
"""`progress(stage, seconds, message)`: called once per finished stage. One that raises (a
cancelled run) stops the calibration before the next stage starts."""
IterationProgress = Callable[[int, int], None]
"""`on_iteration(iteration, max_iterations)`: called after each iteration of the optimisation."""


@dataclass(frozen=True)
class Listeners:
    """Who hears how the calibration gets on: `progress` from the loop after every stage,
    `on_iteration` from the optimisation stage within it."""

    progress: Progress | None = None
    on_iteration: IterationProgress | None = None


@dataclass(frozen=True)
class StageOutcome:
    """What one stage returns: the new state, its details for `result.json` and its one-line
    message for progress. `credited_seconds` is added to the loop's wall time of the stage: time
    spent inside another stage on this one's work (negative for the stage that spent it)."""

    state: CalibrationState
    details: Mapping[str, Detail]
    message: str
    credited_seconds: float = 0.0


StageRun = Callable[[CalibrationState, PipelineConfig, Listeners], StageOutcome]
"""A stage: the state and the config in, the new state and what it did out."""


@dataclass(frozen=True)
class Stage:
    """A stage under the name it is reported by (`result.json`'s `stages`, progress)."""

    name: str
    run: StageRun


def stage_names(stages: Sequence[Stage]) -> tuple[str, ...]:
    """The stages' names in order; one name twice would merge two stages' reports."""
    names = tuple(stage.name for stage in stages)
    if len(set(names)) != len(names):
        raise ValueError(f"each stage needs its own name; the sequence has {list(names)}")
    return names


def run_stages(
    state: CalibrationState,
    config: PipelineConfig,
    stages: Sequence[Stage],
    listeners: Listeners,
) -> tuple[CalibrationState, dict[str, StageReport]]:
    """Run `stages` in order on `state`; the final state and one report per stage, in order."""
    stage_names(stages)
    reports: dict[str, StageReport] = {}
    for stage in stages:
        started = time.perf_counter()
        outcome = stage.run(state, config, listeners)
        seconds = time.perf_counter() - started + outcome.credited_seconds
        reports[stage.name] = StageReport(seconds, dict(outcome.details))
        state = outcome.state
        if listeners.progress is not None:
            listeners.progress(stage.name, seconds, outcome.message)
    return state, reports
