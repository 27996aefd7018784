"""One attempt of a run, as the pool's child process runs it: fetch the recording from storage,
read it, calibrate it with the robot's tolerances in the verdict, compare the extrinsics with the
reference poses, and return the `result.json` document with the worker's stage timings.

Only the pool's children import this module (the fork server preloads it, so the numerical core
is imported once per worker, not once per child); the worker's parent never does.
"""

from __future__ import annotations

import logging
import re
import tempfile
import time
from functools import cache
from pathlib import Path
from typing import Any

from pipeline import (
    STAGES,
    CalibrationProblem,
    CalibrationResult,
    ConfigError,
    PipelineConfig,
    PipelineError,
    calibrate_problem,
    config_from_mapping,
    load_renderer,
    render_report,
    result_document,
)
from pipeline.io import read_recording
from service.reports import store_report_images
from service.run_config import verdict_refusal
from service.settings import Settings
from service.storage import Storage, make_storage
from workers import drift
from workers.context import JobSpec
from workers.pool import Report

log = logging.getLogger(__name__)

# The fork server imports this module once: matplotlib comes with every child then, not inside
# each child's first report.
load_renderer()

_SUFFIXES = {
    "mcap": ".mcap",
    "sqlite3": ".db3",
    "ros1": ".bag",
    "zip": ".zip",
    "tar": ".tar",
    "tar.gz": ".tar.gz",
}


@cache
def _storage(settings: Settings) -> Storage:
    # One client per child process and storage: S3 clients are costly to build.
    return make_storage(settings)


# Where each stage starts, as a fraction of a typical run (the joint optimisation dominates).
_STAGE_PROGRESS = {
    "download": 0.01,
    "read": 0.03,
    "downsample": 0.05,
    "denoise": 0.06,
    "segmentation": 0.14,
    "rough_refinement": 0.2,
    "global_alignment": 0.21,
    "optimisation": 0.22,
    "metric": 0.92,
    "surface_sensitivity": 0.93,
    "observability": 0.94,
    "verdict": 0.96,
    "drift": 0.98,
    "report": 0.99,
}
ITERATION_HALF_LIFE = 10
"""Iterations after which half of the optimisation's share of the progress bar is shown. The
optimisation stops when it converges, which it does long before `max_iterations` (200) on a good
recording, so progress by `k / max_iterations` would crawl, then jump; `1 - 2^(-k / 10)` moves
at every iteration and never claims the end early."""
REPORT_INTERVAL_S = 0.5
"""At most this often per run: each report is a database write in the worker."""


def optimisation_progress(iteration: int, max_iterations: int) -> float:
    """Where a run is after `iteration` of the optimisation, between its stage and the next."""
    start, end = _STAGE_PROGRESS["optimisation"], _STAGE_PROGRESS["metric"]
    if iteration >= max_iterations:
        return end
    left: float = 0.5 ** (iteration / ITERATION_HALF_LIFE)
    return start + (end - start) * (1 - left)


# The tolerance profile's limits that are the pipeline verdict's own (`VerdictConfig`); the drift
# and design limits come with the reference poses (`workers.drift`), judged by the same verdict.
_VERDICT_LIMITS = (
    "max_metric_error_m",
    "max_seen_metric_error_m",
    "max_translation_stddev_m",
    "max_rotation_stddev_deg",
)


def pipeline_config_for(
    run_config: dict[str, Any] | None, limits: dict[str, Any]
) -> PipelineConfig:
    """The `PipelineConfig` of a run: the upload's config (`X-Fleetcal-Config`: reference LiDAR,
    initial extrinsics, reader and stage settings) with the verdict's limits from the robot's
    tolerance profile. The upload may not set the verdict: a robot must not loosen its own."""
    data = dict(run_config or {})
    if (refusal := verdict_refusal(data)) is not None:
        raise ConfigError(f"the upload's config {refusal}")
    data["verdict"] = {name: limits[name] for name in _VERDICT_LIMITS if name in limits}
    return config_from_mapping(data)


_SCRATCH = re.compile(re.escape(tempfile.gettempdir()) + r"/fleetcal-[\w-]+/(unpacked/)?")
"""A folder of this worker's (the run's, or the reader's for an unpacked archive)."""


def without_scratch_paths(err: PipelineError, recording: Path) -> PipelineError:
    """`err`, its message rid of the worker's temporary paths: the user uploaded a recording,
    not `/tmp/fleetcal-run-x/recording.tar`, and a path inside an archive reads from the archive's
    own root. The same exception (type and traceback), for the retry policy."""
    message = str(err).replace(str(recording), "the uploaded recording")
    err.args = (_SCRATCH.sub("", message),)
    return err


def calibrate_run(spec: JobSpec, report: Report) -> dict[str, Any]:
    """Download, read and calibrate the run's recording; the `result.json` document."""

    reached = [0.0]

    def stage(name: str) -> None:
        reached[0] = _STAGE_PROGRESS.get(name, reached[0])
        report(name, reached[0])

    def after(finished: str, *details: object) -> None:
        # `calibrate` reports a stage when it ends; the run is then in the next one.
        index = STAGES.index(finished) if finished in STAGES else len(STAGES)
        if index + 1 < len(STAGES):
            stage(STAGES[index + 1])

    last_report = [0.0]

    def iteration(done: int, max_iterations: int) -> None:
        now = time.monotonic()
        if now - last_report[0] >= REPORT_INTERVAL_S:
            last_report[0] = now
            reached[0] = optimisation_progress(done, max_iterations)
            report("optimisation", reached[0])

    config = pipeline_config_for(spec.config, spec.context.limits)
    with tempfile.TemporaryDirectory(prefix="fleetcal-run-") as scratch:
        stage("download")
        started = time.perf_counter()
        path = Path(scratch) / f"recording{_SUFFIXES.get(spec.upload_format, '')}"
        _storage(spec.settings).download(spec.storage_key, path)
        download_seconds = time.perf_counter() - started

        stage("read")
        started = time.perf_counter()
        try:
            problem = read_recording(path, config.reader)
        except PipelineError as err:
            raise without_scratch_paths(err, path) from err.__cause__
        read_seconds = time.perf_counter() - started

    stage(STAGES[0])
    result = calibrate_problem(problem, config, progress=after, on_iteration=iteration)
    if spec.context.reference is not None:
        stage("drift")
        result = drift.judged_against(result, spec.context.reference)
    document = result_document(result, read_seconds=read_seconds)
    document["stages"] = {"download": {"seconds": download_seconds}, **document["stages"]}
    document["tolerance_profile"] = spec.context.profile
    stage("report")
    started = time.perf_counter()
    document["report"] = _report_images(spec, problem, result, result.verdict.passed)
    document["stages"]["report"] = {"seconds": time.perf_counter() - started}
    return document


def _report_images(
    spec: JobSpec, problem: CalibrationProblem, result: CalibrationResult, passed: bool
) -> dict[str, Any]:
    """Draw the run's report images and store them with the run (`service.reports`). A drawing
    failure is noted in the result and never costs a good calibration; a storage error goes to
    the retry policy like any other."""
    try:
        images = render_report(problem, result, passed=passed)
    except Exception as err:
        log.exception("run %s: the report images could not be drawn", spec.run_id)
        return {"images": [], "error": f"the report images could not be drawn ({err})"}
    return {"images": store_report_images(_storage(spec.settings), spec.run_id, images)}
