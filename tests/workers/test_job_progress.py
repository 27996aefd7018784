"""A run's progress, as the worker's job reports it on the `tiny` recording: it advances through
every stage and, within the optimisation, iteration by iteration (it used to jump 22 % -> 92 %)."""

from __future__ import annotations

import uuid
from pathlib import Path

import pytest

from pipeline.io.formats import detect_format_from_head
from service.settings import Settings
from service.storage import make_storage
from tests.workers.test_end_to_end import tiny_recording  # noqa: F401 (the fixture)
from workers import job
from workers.context import JobSpec

pytestmark = pytest.mark.slow


def test_progress_advances_through_the_stages_and_iterations(
    tiny_recording: bytes,  # noqa: F811 (the fixture)
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(job, "REPORT_INTERVAL_S", 0.0)  # every iteration, to see each one
    settings = Settings(data_dir=tmp_path, storage_url=(tmp_path / "storage").as_uri())
    run_id = uuid.uuid4()
    key = f"recordings/R1/{run_id}"
    pending = make_storage(settings).begin_upload(key)
    pending.write(tiny_recording)
    pending.commit()
    detected = detect_format_from_head(tiny_recording[:4096])
    assert detected is not None
    reports: list[tuple[str, float]] = []
    spec = JobSpec(
        run_id=str(run_id),
        attempt=1,
        robot_id="R1",
        kind="end_of_line",
        storage_key=key,
        upload_format=detected.value,
        config={"optimisation": {"max_iterations": 20, "max_points_per_cloud": 200}},
        settings=settings,
    )
    document = job.calibrate_run(spec, lambda name, progress: reports.append((name, progress)))
    progress = [value for _, value in reports]
    assert progress == sorted(progress), reports
    during = [value for name, value in reports if name == "optimisation"]
    optimisation = document["stages"]["optimisation"]
    # Global alignment's candidate, where it finds one, is a second start: both runs report.
    iterations = optimisation.get("iterations_all_starts", optimisation["iterations"])
    assert len(during) == iterations + 1, "the stage's start, then one report per iteration"
    assert len(set(during)) == len(during) and during[-1] <= job._STAGE_PROGRESS["metric"]
    stages = [name for name, _ in reports]
    for stage in ("download", "read", "segmentation", "optimisation", "metric", "report"):
        assert stage in stages
