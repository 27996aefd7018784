import dataclasses
import time

import numpy as np
import pytest

from pipeline.config import PipelineConfig
from pipeline.stages.runner import Listeners, Stage, StageOutcome, run_stages, stage_names
from pipeline.stages.state import CalibrationState


def empty_state() -> CalibrationState:
    """A state without LiDARs or clouds: enough for stages that only count."""
    poses = np.eye(4)[np.newaxis]
    return CalibrationState(
        lidars=(),
        clouds_in_lidar=(),
        up_in_lidar=(),
        T_G_ref_initial=poses,
        T_ref_lidar_initial=poses,
        T_G_ref=poses,
        T_ref_lidar=poses,
    )


def stepping(name: str, ran: list[str], *, sleep_s: float = 0.0, credit_s: float = 0.0) -> Stage:
    """A stage that notes it ran and moves the state's floor time on by one."""

    def run(state: CalibrationState, config: PipelineConfig, listeners: Listeners) -> StageOutcome:
        ran.append(name)
        time.sleep(sleep_s)
        moved = dataclasses.replace(state, floor_seconds=state.floor_seconds + 1)
        return StageOutcome(moved, {"step": len(ran)}, f"{name} done", credited_seconds=credit_s)

    return Stage(name, run)


def test_stages_run_in_order_each_on_the_state_before_with_one_report_and_one_progress() -> None:
    ran: list[str] = []
    heard: list[tuple[str, float, str]] = []
    stages = [stepping(name, ran) for name in ("first", "second", "third")]
    state, reports = run_stages(
        empty_state(),
        PipelineConfig(),
        stages,
        Listeners(progress=lambda stage, seconds, message: heard.append((stage, seconds, message))),
    )
    assert ran == ["first", "second", "third"]
    assert state.floor_seconds == 3  # each stage got the state the one before returned
    assert list(reports) == ["first", "second", "third"]
    assert [dict(report.details) for report in reports.values()] == [{"step": k} for k in (1, 2, 3)]
    assert heard == [(name, reports[name].seconds, f"{name} done") for name in reports]


def test_a_stage_is_timed_by_the_loop_with_what_it_credits() -> None:
    ran: list[str] = []
    stages = [stepping("slow", ran, sleep_s=0.05), stepping("credited", ran, credit_s=2.0)]
    _, reports = run_stages(empty_state(), PipelineConfig(), stages, Listeners())
    assert 0.05 <= reports["slow"].seconds < 1.0
    assert 2.0 <= reports["credited"].seconds < 3.0


def test_a_listener_that_raises_stops_the_run_before_the_next_stage() -> None:
    ran: list[str] = []

    def cancel(stage: str, seconds: float, message: str) -> None:
        if stage == "first":
            raise KeyboardInterrupt

    stages = [stepping(name, ran) for name in ("first", "second")]
    with pytest.raises(KeyboardInterrupt):
        run_stages(empty_state(), PipelineConfig(), stages, Listeners(progress=cancel))
    assert ran == ["first"]


def test_two_stages_of_one_name_are_refused_before_any_runs() -> None:
    ran: list[str] = []
    stages = [stepping("same", ran), stepping("other", ran), stepping("same", ran)]
    assert stage_names(stages[:2]) == ("same", "other")
    with pytest.raises(ValueError, match=r"its own name.*\['same', 'other', 'same'\]"):
        run_stages(empty_state(), PipelineConfig(), stages, Listeners())
    assert ran == []
