import dataclasses

import numpy as np
import pytest

from pipeline.metric import SolutionComparison
from pipeline.stages.state import per_cloud
from tests.pipeline.stages.test_global_align import _after_stage_3


def test_stage_4s_two_solutions_reach_the_verdict_as_evidence() -> None:
    state = _after_stage_3()
    assert state.starts_evidence() is None
    compared = SolutionComparison(3.49, 9.11, -0.0022, 0.0026, 477)
    starts = dataclasses.replace(state, start_comparison=compared).starts_evidence()
    assert starts is not None
    assert (starts.apart_translation_m, starts.apart_rotation_deg) == (3.49, 9.11)
    assert starts.separation_sigmas == compared.separation_sigmas


def test_per_cloud_keeps_each_lidars_row_of_stops(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    clouds = ((np.zeros((1, 3)),) * 3, (np.zeros((2, 3)),) * 2)
    assert per_cloud(clouds, lambda at: at) == (((0, 0), (0, 1), (0, 2)), ((1, 0), (1, 1)))
    assert per_cloud((), lambda at: at) == ()
