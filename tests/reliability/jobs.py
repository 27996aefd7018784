"""Job functions for the fault tests: the real calibration (`workers.job.calibrate_run`), held at a
chosen stage so that a test can kill its worker there.

A run's config may carry `"pause_at": {"<attempt>": "<stage>"}`: on that attempt, once the run has
reached that stage (the worker has recorded it), the pipeline process waits forever for the kill;
or `"hold_at": {"<attempt>": ["<stage>", "<file>"]}`: it waits there until the file exists, then
goes on. Both keys are removed before the pipeline sees the config."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

from workers.context import JobSpec
from workers.job import calibrate_run
from workers.pool import Report

PAUSED_CALIBRATION = "tests.reliability.jobs:paused_calibration"


def paused_calibration(spec: JobSpec, report: Report) -> dict[str, Any]:
    config = dict(spec.config or {})
    pause_at = config.pop("pause_at", {}).get(str(spec.attempt))
    hold_at, release = config.pop("hold_at", {}).get(str(spec.attempt), (None, ""))
    spec = dataclasses.replace(spec, config=config or None)

    def reported(name: str, progress: float) -> None:
        report(name, progress)
        if name == pause_at:
            while True:  # until the test kills this worker
                time.sleep(3600)
        if name == hold_at:
            while not Path(release).exists():
                time.sleep(0.05)

    return calibrate_run(spec, reported)
