"""Downloads in headless Chromium: the CSV exports and a run's text exports are fetched with the key
in a header and saved from a Blob (api.js, ui.js); each saved file is read back by an independent
reader (the csv module, PyYAML) and matched against the API's JSON and the stored result."""

from __future__ import annotations

import csv
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.pipeline.test_export import assert_same, parse_autoware
from tests.service.dashboard.browser import api_json, downloaded, open_page, sign_in, wait_for
from tests.service.dashboard.conftest import LiveApp

POSE = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")


@pytest.fixture(scope="module")
def signed_in(browser: Any, live_app: LiveApp) -> Any:
    sign_in(browser, live_app.url, live_app.read_key)
    return browser


@pytest.fixture
def downloads(download_dir: Path) -> Iterator[Path]:
    """The browser's download folder, empty for each test."""
    for path in download_dir.iterdir():
        path.unlink()
    yield download_dir


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as file:
        return list(csv.DictReader(file))


def pose_cells(row: dict[str, str]) -> list[float]:
    return [float(row[name]) for name in POSE]


def save(browser: Any, app: LiveApp, route: str, button: str, folder: Path, name: str) -> Path:
    """Open `route`, press `button` and wait for the browser to save `name`."""
    open_page(browser, app.url, route)
    wait_for(browser, button)[0].click()
    return downloaded(folder, name)


def test_a_robots_history_csv_holds_what_the_api_says(
    signed_in: Any, live_app: LiveApp, downloads: Path
) -> None:
    rows = read_csv(
        save(signed_in, live_app, "/robots/R1", "#history-csv", downloads, "R1-history.csv")
    )
    want = api_json(live_app.url, live_app.read_key, "/v1/robots/R1/history?limit=500")["items"]
    assert len(rows) == len(want) == 6  # three runs, two LiDARs
    for row, point in zip(rows, want, strict=True):
        assert (row["robot_id"], row["run_id"], row["frame"]) == (
            "R1",
            point["run_id"],
            point["frame"],
        )
        assert (row["passed"], row["accepted"], row["is_reference"]) == (
            str(point["passed"]),
            str(point["accepted"]),
            str(point["is_reference"]),
        )
        assert pose_cells(row) == [*point["translation"], *point["rotation_xyzw"]]  # exact
    assert {r["run_id"] for r in rows if r["passed"] == "False"} == {str(live_app.fleet.hit)}
    # Accepted calibrations only: the hit mount's failed run is left out.
    (downloads / "R1-history.csv").unlink()
    wait_for(signed_in, "#accepted-csv")[0].click()
    accepted = read_csv(downloaded(downloads, "R1-history.csv"))
    assert [r["run_id"] for r in accepted] == [r["run_id"] for r in rows if r["accepted"] == "True"]


def test_the_fleets_calibrations_csv_holds_each_robots_calibration_in_use(
    signed_in: Any, live_app: LiveApp, downloads: Path
) -> None:
    rows = read_csv(
        save(signed_in, live_app, "/", "#fleet-csv", downloads, "fleet-calibrations.csv")
    )
    fleet = api_json(live_app.url, live_app.read_key, "/v1/fleet?limit=500")["items"]
    in_use = {
        robot["id"]: robot["latest_calibration"]["run_id"] if robot["latest_calibration"] else ""
        for robot in fleet
    }
    assert {row["robot_id"]: row["run_id"] for row in rows} == in_use
    # R4's newest run failed: its calibration in use is the one before, as the API says.
    assert in_use["R4"] == str(live_app.fleet.r4_accepted[1])
    calibration = api_json(live_app.url, live_app.read_key, "/v1/robots/R4/calibration")
    for row in (r for r in rows if r["robot_id"] == "R4"):
        lidar = calibration["lidars"][row["frame"]]
        assert pose_cells(row) == [*lidar["translation"], *lidar["rotation_xyzw"]]


def test_a_runs_autoware_export_downloads_and_parses_to_the_result(
    signed_in: Any, live_app: LiveApp, downloads: Path
) -> None:
    run = live_app.fleet.repaired
    button = '#downloads button[data-format="autoware"]'
    name = f"R1-{run.hex[:8]}-sensor_kit_calibration.yaml"
    text = save(signed_in, live_app, f"/runs/{run}", button, downloads, name).read_text()
    assert_same(parse_autoware(text), live_app.fleet.documents[run])


def test_a_refused_download_shows_the_apis_reason(
    signed_in: Any, live_app: LiveApp, downloads: Path
) -> None:
    from selenium.webdriver.support.ui import WebDriverWait

    open_page(signed_in, live_app.url, f"/runs/{live_app.fleet.hit}")
    wait_for(signed_in, '#downloads button[data-format="urdf"]')[0].click()
    message = wait_for(signed_in, "#download-error")[0]
    WebDriverWait(signed_in, 30).until(lambda _: message.text)
    assert message.text.startswith("URDF snippet: ")
    assert "drift_translation:lidar_rear" in message.text
    assert list(downloads.iterdir()) == []
