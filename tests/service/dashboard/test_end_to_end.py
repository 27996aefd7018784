"""The dashboard after a real run, as a new user sees it after `fleetcal demo`: a synthesised
`tiny` recording uploaded through the API, calibrated by the embedded service's worker (which
draws and stores the report images), then the run page in headless Chromium."""

from __future__ import annotations

import io
import json
import tarfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.auth import create_key
from service.db import Database
from service.models import Scope
from service.settings import Settings
from tests.service.dashboard.browser import open_page, screenshot, wait_for

# Few iterations: this is about what the dashboard shows of a run, not about its accuracy.
RUN_CONFIG = {"optimisation": {"max_iterations": 30}}
RUN_DEADLINE_S = 300


@dataclass(frozen=True)
class Served:
    url: str
    admin_key: str
    run_id: str


@pytest.fixture(scope="module")
def served_run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """The embedded service (API + one worker) with one finished run of the `tiny` scenario."""
    from pipeline.synth import write_recording
    from pipeline.synth.recording import RECORDING_DIR
    from workers.embedded import EmbeddedService
    from workers.worker import WorkerOptions

    synth = tmp_path_factory.mktemp("tiny") / "synth"
    write_recording("tiny", synth, seed=0)
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        tar.add(synth / RECORDING_DIR, arcname=RECORDING_DIR)

    settings = Settings(data_dir=tmp_path_factory.mktemp("served"))
    db = Database.from_settings(settings)
    db.upgrade()
    with db.transaction() as session:
        admin = create_key(session, [Scope.ADMIN]).secret
    db.dispose()
    options = WorkerOptions(poll_interval=timedelta(milliseconds=100))
    with (
        EmbeddedService(settings, port=0, workers=1, options=options) as service,
        httpx.Client(base_url=service.url, headers={"X-API-Key": admin}, timeout=60) as client,
    ):
        response = client.post(
            "/v1/robots/demo-robot/runs",
            params={"kind": "end_of_line"},
            content=buffer.getvalue(),
            headers={"X-Fleetcal-Config": json.dumps(RUN_CONFIG)},
        )
        assert response.status_code == 202, response.text
        run_id = response.json()["id"]
        deadline = time.monotonic() + RUN_DEADLINE_S
        while (run := client.get(f"/v1/runs/{run_id}").json())["status"] not in (
            "succeeded",
            "failed",
        ):
            assert time.monotonic() < deadline, f"run {run_id} did not finish: {run}"
            time.sleep(0.5)
        assert run["status"] == "succeeded", run["error"]
        yield Served(service.url, admin, run_id)


pytestmark = pytest.mark.slow


def test_the_worker_stores_the_report_images(served_run: Served) -> None:
    with httpx.Client(
        base_url=served_run.url, headers={"X-API-Key": served_run.admin_key}
    ) as client:
        run = client.get(f"/v1/runs/{served_run.run_id}").json()
        assert run["result"]["report"]["images"] == ["map-top", "map-side", "error"]
        assert run["result"]["stages"]["report"]["seconds"] > 0
        index = client.get(f"/v1/runs/{served_run.run_id}/report").json()
        assert [image["name"] for image in index["images"]] == ["map-top", "map-side", "error"]
        png = client.get(index["images"][0]["url"])
        assert png.headers["content-type"] == "image/png"
        assert png.content.startswith(b"\x89PNG")


def test_a_new_user_sees_the_robot_its_run_and_the_images(
    served_run: Served, browser: Any, artifacts_dir: Path
) -> None:
    browser.get(f"{served_run.url}/")
    wait_for(browser, "#api-key")[0].send_keys(served_run.admin_key)
    wait_for(browser, "#key-form button")[0].click()
    rows = wait_for(browser, "table#fleet tbody tr")
    assert [row.get_attribute("data-robot-id") for row in rows] == ["demo-robot"]
    open_page(browser, served_run.url, f"/runs/{served_run.run_id}")
    assert wait_for(browser, "#verdict [data-verdict]")
    images = wait_for(browser, 'img.report-image[data-loaded="true"]', count=3)
    for image in images:
        assert browser.execute_script("return arguments[0].naturalWidth", image) >= 800
    assert "after" in wait_for(browser, "#metric-error")[0].text
    screenshot(browser, artifacts_dir, "end-to-end-run")
