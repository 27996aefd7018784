import dataclasses

from pipeline.metric import SolutionComparison
from tests.pipeline.stages.test_global_align import _after_stage_3


def test_stage_4s_two_solutions_reach_the_verdict_as_evidence() -> None:
    state = _after_stage_3()
    assert state.starts_evidence() is None
    compared = SolutionComparison(3.49, 9.11, -0.0022, 0.0026, 477)
    starts = dataclasses.replace(state, start_comparison=compared).starts_evidence()
    assert starts is not None
    assert (starts.apart_translation_m, starts.apart_rotation_deg) == (3.49, 9.11)
    assert starts.separation_sigmas == compared.separation_sigmas
