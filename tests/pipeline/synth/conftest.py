"""Shared, session-scoped synthetic problems: simulated once, read by many tests."""

from __future__ import annotations

import pytest

from pipeline.problem import CalibrationProblem
from pipeline.synth import Truth, simulate_problem


@pytest.fixture(scope="session")
def tiny_problem() -> tuple[CalibrationProblem, Truth]:
    return simulate_problem("tiny", seed=7)
