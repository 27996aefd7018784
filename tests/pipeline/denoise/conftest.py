"""The synthesiser's labelled stop clouds, simulated once per session."""

from __future__ import annotations

import pytest

from tests.pipeline.denoise.clouds import LabelledCloud, synth_stop_clouds


@pytest.fixture(scope="session")
def tiny_stop_clouds() -> list[LabelledCloud]:
    """Every stop cloud of every LiDAR of the `tiny` scenario (Mid-70 at 5 % rate, boxes), for two
    seeds: about 47k points, 500 of them bleeding."""
    return list(synth_stop_clouds("tiny", seeds=(3, 7)))
