"""The dashboard shows the roll, pitch and yaw the API derives (`rpy_deg`), computing none."""

from __future__ import annotations

from typing import Any

from pipeline.result_model import rpy_deg
from tests.service.dashboard import test_browser
from tests.service.dashboard.browser import open_page, wait_for
from tests.service.dashboard.conftest import LiveApp

signed_in = test_browser.signed_in  # the fixture: the browser with the read key entered


def _angles(rotation_xyzw: list[float]) -> str:
    return "[" + ", ".join(f"{v:.3f}" for v in rpy_deg(tuple(rotation_xyzw))) + "]°"  # type: ignore[arg-type]


def test_a_run_shows_each_pose_with_the_api_angles(signed_in: Any, live_app: LiveApp) -> None:
    run = live_app.fleet.repaired
    lidar = live_app.fleet.documents[run]["lidars"]["lidar_rear"]
    open_page(signed_in, live_app.url, f"/runs/{run}")
    row = wait_for(signed_in, '#lidars tr[data-frame="lidar_rear"]')[0].text
    assert _angles(lidar["initial"]["rotation_xyzw"]) in row
    assert _angles(lidar["calibrated"]["rotation_xyzw"]) in row


def test_the_robot_page_shows_the_latest_accepted_angles(signed_in: Any, live_app: LiveApp) -> None:
    run = live_app.fleet.repaired  # the robot's newest accepted calibration
    calibrated = live_app.fleet.documents[run]["lidars"]["lidar_rear"]["calibrated"]
    open_page(signed_in, live_app.url, "/robots/R1")
    rear = wait_for(signed_in, 'article.lidar[data-frame="lidar_rear"]')[0].text
    assert f"roll/pitch/yaw = {_angles(calibrated['rotation_xyzw'])}" in rear
