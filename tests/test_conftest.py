"""`unavailable`: without PostgreSQL or Chromium their tests are skipped, under CI=true they fail.

Each case runs pytest in a subprocess on a real test of each kind, with the server's address
pointing at a closed port and no Chromium on the PATH."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
NEEDS_POSTGRES = "tests/service/test_db.py::test_foreign_keys_are_enforced[postgres]"
NEEDS_CHROMIUM = "tests/service/dashboard/test_browser.py::test_a_wrong_key_is_refused_in_the_form"
PYTEST = (sys.executable, "-m", "pytest", "-n", "0", "-p", "no:cacheprovider", "-q", "-rfEs")


def closed_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def run_without_servers(tmp_path: Path, ci: str | None) -> subprocess.CompletedProcess[str]:
    dropped = {"CI", "FLEETCAL_CHROMIUM", "FLEETCAL_CHROMEDRIVER"}
    env = {name: value for name, value in os.environ.items() if name not in dropped}
    env |= {
        "FLEETCAL_TEST_PG_ADMIN_DSN": f"postgresql://postgres@127.0.0.1:{closed_port()}/postgres",
        "PATH": str(tmp_path),  # no chromium, no chromedriver
        "PYTHONPATH": str(REPO_ROOT),
    }
    if ci is not None:
        env["CI"] = ci
    return subprocess.run(
        [*PYTEST, NEEDS_POSTGRES, NEEDS_CHROMIUM],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.slow
def test_a_missing_server_or_browser_skips_its_tests_with_the_reason(tmp_path: Path) -> None:
    done = run_without_servers(tmp_path, ci=None)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 skipped" in done.stdout.strip().splitlines()[-1]
    assert "is unreachable" in done.stdout and "headless Chromium is not installed" in done.stdout


@pytest.mark.slow
def test_under_ci_a_missing_server_or_browser_fails_the_run(tmp_path: Path) -> None:
    done = run_without_servers(tmp_path, ci="true")
    assert done.returncode == 1, done.stdout + done.stderr
    summary = done.stdout.strip().splitlines()[-1]
    assert "2 errors" in summary and "skipped" not in summary, summary
    assert "is unreachable" in done.stdout and "headless Chromium is not installed" in done.stdout
    assert "CI=true: CI must run these tests" in done.stdout
