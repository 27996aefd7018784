import pytest

from pipeline.config import PipelineConfig
from pipeline.stages.runner import Listeners, run_stages
from pipeline.stages.sequence import STAGE_SEQUENCE, STAGES
from pipeline.stages.setup import initial_state
from pipeline.stages.state import StageOrderError
from tests.pipeline.calibration_data import box_problem


def test_the_stage_names_are_the_sequences_in_order() -> None:
    assert tuple(stage.name for stage in STAGE_SEQUENCE) == STAGES
    assert STAGES[:2] == ("moving_points", "denoise") and STAGES[-1] == "verdict"


def test_a_stage_moved_before_what_it_needs_says_which_stage_must_come_first() -> None:
    config = PipelineConfig()
    state = initial_state(box_problem()[0], config.frames)
    moving, denoise, segmentation, *rest = STAGE_SEQUENCE
    with pytest.raises(StageOrderError, match="'denoise' has not run: put it before this one"):
        run_stages(state, config, (moving, segmentation, denoise, *rest), Listeners())
