"""Settings for the whole suite, and `unavailable` for tests that need a server or a browser."""

import os
from typing import NoReturn

import pytest
from hypothesis import settings

# `.ci/run` draws the same examples on every run, so that CI goes red only when a change breaks
# something. Anywhere else the property tests (the fuzzers in tests/reliability) draw afresh each
# run and keep looking for damage the code does not handle yet.
settings.register_profile("ci", derandomize=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def in_ci() -> bool:
    """Whether this is CI (`CI=true`, as CI services and `.ci/run` set it)."""
    return os.environ.get("CI", "").strip().lower() in {"1", "true", "yes"}


def unavailable(reason: str) -> NoReturn:
    """Skip a test that needs what this machine lacks (PostgreSQL, Chromium), with the reason;
    under `CI=true` fail it instead: CI installs them, and a skip there would let a whole class of
    tests go unrun while the run stays green."""
    if in_ci():
        pytest.fail(
            f"{reason} (CI=true: CI must run these tests, it does not skip them)", pytrace=False
        )
    pytest.skip(reason)
