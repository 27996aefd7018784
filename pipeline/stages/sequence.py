"""The calibration's stages, in the order they run: the one place to add, drop or reorder one.

Each stage is a module with `run(state, config, listeners) -> StageOutcome`; its name is the key
of its report in `result.json`'s `stages` and what progress shows. The loop that runs them is
`pipeline.stages.runner.run_stages`."""

from __future__ import annotations

from pipeline.stages import (
    decide,
    denoise_stage,
    floor_refine,
    global_align,
    joint_optimise,
    measure,
    moving,
    observe,
    segment,
    sensitivity,
)
from pipeline.stages.runner import Stage, stage_names

STAGE_SEQUENCE: tuple[Stage, ...] = (
    Stage("moving_points", moving.run),
    Stage("denoise", denoise_stage.run),
    Stage("segmentation", segment.run),
    Stage("rough_refinement", floor_refine.run),
    Stage("global_alignment", global_align.run),
    Stage("optimisation", joint_optimise.run),
    Stage("metric", measure.run),
    Stage("surface_sensitivity", sensitivity.run),
    Stage("observability", observe.run),
    Stage("verdict", decide.run),
)

STAGES: tuple[str, ...] = stage_names(STAGE_SEQUENCE)
"""The stages' names in order (the worker's progress moves through them)."""
