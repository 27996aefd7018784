"""Job functions for testing the worker's process pool and queue handling without the pipeline's
cost: `scripted` does what the run's config asks (sleep, fail with bad input, die, hang) and
returns a real `result.json`; the benchmark drains runs with it as well."""

from __future__ import annotations

import os
import signal
import time
from typing import Any

from pipeline.errors import BadInputError
from service.storage import StorageError
from tests.service.documents import result_document
from workers.context import JobSpec
from workers.pool import BLAS_THREAD_VARIABLES, Report

SCRIPTED = "tests.workers.jobs:scripted"


def scripted(spec: JobSpec, report: Report) -> dict[str, Any]:
    """Config keys: `sleep` (s), `fail` ("bad_input" | "storage"), `die_on_attempts` (list of
    attempt numbers on which the process kills itself), `report_environment` (bool), `warnings`
    (the result's)."""
    script = spec.config or {}
    report("work", 0.5)
    if spec.attempt in script.get("die_on_attempts", ()):
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(float(script.get("sleep", 0)))
    if script.get("fail") == "bad_input":
        raise BadInputError("the recording has no stops: the robot never stood still for 1 s")
    if script.get("fail") == "storage":
        raise StorageError("cannot read the recording: connection reset by peer")
    document = result_document()
    document["worker"] = {"pid": os.getpid(), "attempt": spec.attempt}
    if "warnings" in script:
        document["warnings"] = script["warnings"]
    if script.get("report_environment"):
        document["worker"]["environment"] = {v: os.environ.get(v) for v in BLAS_THREAD_VARIABLES}
    return document
