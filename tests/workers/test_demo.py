"""`fleetcal demo --once` as a user runs it (on the tiny scenario, to stay quick): every step is
printed, the extrinsics are compared with the truth, and the exit status is the verdict's."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.workers.runs import ROOT, entrypoint_env
from workers.cli import app


@pytest.mark.slow
def test_demo_once_runs_the_main_job_and_exits_with_the_verdict(tmp_path: Path) -> None:
    done = subprocess.run(
        [
            "fleetcal",
            "demo",
            "--once",
            "--data-dir",
            str(tmp_path),
            "--port",
            "0",
            "--scenario",
            "tiny",
            "--rate-scale",
            "1.0",
        ],
        env=entrypoint_env(),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    out = done.stdout
    for step in range(1, 6):
        assert f"[{step}/5]" in out, done.stderr
    assert re.search(r"\[3/5\] upload    run [0-9a-f-]{36} for robot demo-1", out)
    assert "succeeded" in out, "the run's progress ends in its final status"
    passed = "verdict   PASSED" in out
    assert passed or "verdict   NOT PASSED" in out
    assert done.returncode == (0 if passed else 1)
    # Each LiDAR: its calibrated pose and its error against the truth (or why there is none).
    assert re.search(r"lidar_front\* .* mm .* deg -> .* mm .* deg \(T_base_lidar", out)
    assert re.search(
        r"lidar_rear +(\S+ +){6}.* mm .* -> .* \(relative to lidar_front\)"
        r"|lidar_rear +undetermined by the data",
        out,
    )
    # The first start's admin key is shown as `serve` shows it, and the hint names the directory.
    assert "Created the first admin key; it is shown only this once, store it now:\n  fck_" in out
    assert f"`fleetcal keys create --scope read --data-dir {tmp_path}`" in out
    assert "[1/5] service   http://127.0.0.1:" in out and f"(data directory {tmp_path})" in out
    assert (tmp_path / "fleetcal.db").is_file(), "the state lives under --data-dir"


def test_demo_with_a_bad_setting_stops_before_it_creates_a_key(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app,
        ["demo", "--once", "--data-dir", str(tmp_path / "state"), "--port", "0"],
        env={"FLEETCAL_STORAGE_URL": "storage"},
    )
    assert result.exit_code == 2 and isinstance(result.exception, SystemExit)
    assert result.stderr == (
        "error: FLEETCAL_STORAGE_URL: unsupported storage URL 'storage': use file:///absolute/dir "
        "or s3://bucket[/prefix]\n"
    )
    assert result.stdout == "" and not (tmp_path / "state").exists()
