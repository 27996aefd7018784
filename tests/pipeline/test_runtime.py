"""The process-wide settings of `pipeline.runtime`: OpenMP threads wait passively unless the user
chose otherwise, and glibc's allocator keeps freed blocks for reuse."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline import runtime

ROOT = Path(__file__).resolve().parents[2]


def _wait_policy_after_import(environment: dict[str, str]) -> str:
    probe = "import os, pipeline; print(os.environ.get('OMP_WAIT_POLICY'))"
    done = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=environment,
        timeout=60,
        check=True,
    )
    return done.stdout.strip()


def test_importing_pipeline_makes_openmp_threads_wait_passively() -> None:
    environment = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    assert _wait_policy_after_import(environment) == "PASSIVE"


def test_a_wait_policy_the_user_set_is_kept() -> None:
    environment = {**os.environ, "OMP_WAIT_POLICY": "ACTIVE"}
    assert _wait_policy_after_import(environment) == "ACTIVE"


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or os.confstr("CS_GNU_LIBC_VERSION") is None,
    reason="glibc's mallopt only",
)
def test_the_allocator_is_tuned_once_on_glibc() -> None:
    assert runtime.tune_allocator() is True
    assert runtime.tune_allocator() is True  # cached: mallopt is not called again


def test_another_platform_is_left_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "platform", "darwin")
    runtime.tune_allocator.cache_clear()
    try:
        assert runtime.tune_allocator() is False
    finally:
        runtime.tune_allocator.cache_clear()
