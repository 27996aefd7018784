"""The dashboard in a real browser (headless Chromium) against the running app with a seeded fleet:
the key form, the overview's robots, a robot's drift charts, and run pages with their verdict,
checks, live progress and report images. Screenshots are saved as test artefacts."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.dashboard.conftest import LiveApp

WAIT_S = 30


def wait_for(browser: Any, css: str, count: int = 1) -> list[Any]:
    """The elements matching `css` once there are at least `count` of them."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    def found(driver: Any) -> list[Any] | bool:
        elements = driver.find_elements(By.CSS_SELECTOR, css)
        return elements if len(elements) >= count else False

    result: list[Any] = WebDriverWait(browser, WAIT_S).until(found, f"no {count} x {css}")
    return result


def open_page(browser: Any, base_url: str, route: str) -> None:
    """Go to the dashboard's `route` (e.g. `/robots/R1`) and wait until it has been drawn."""
    from selenium.webdriver.support.ui import WebDriverWait

    target = f"{base_url}/#{route}"
    browser.execute_script(
        "const a = document.getElementById('app'); if (a) a.dataset.ready = 'stale'"
    )
    if browser.current_url == target:
        browser.refresh()
    else:
        browser.get(target)
    WebDriverWait(browser, WAIT_S).until(
        lambda driver: driver.execute_script(
            "const a = document.getElementById('app');"
            "return a.dataset.route === arguments[0] && a.dataset.ready === 'true'",
            route,
        ),
        f"the dashboard did not draw {route}",
    )


def screenshot(browser: Any, artifacts: Path, name: str) -> Path:
    """The whole page: the window is made as tall as the document first."""
    height = browser.execute_script("return document.documentElement.scrollHeight")
    browser.set_window_size(1400, max(900, min(int(height) + 40, 6000)))
    path = artifacts / f"dashboard-{name}.png"
    assert browser.save_screenshot(str(path)), path
    browser.set_window_size(1400, 1000)
    return path


@pytest.fixture(scope="module")
def signed_in(browser: Any, live_app: LiveApp) -> Any:
    """The browser with the read key entered once in the form (kept in session storage)."""
    browser.get(f"{live_app.url}/")
    field = wait_for(browser, "#api-key")[0]
    field.send_keys(live_app.read_key)
    wait_for(browser, "#key-form button")[0].click()
    wait_for(browser, "table#fleet")
    return browser


def test_a_wrong_key_is_refused_in_the_form(browser: Any, live_app: LiveApp) -> None:
    browser.get(f"{live_app.url}/")
    browser.execute_script("sessionStorage.clear()")
    browser.refresh()
    wait_for(browser, "#api-key")[0].send_keys("fck_000000000000_" + "x" * 43)
    wait_for(browser, "#key-form button")[0].click()
    error = wait_for(browser, "#key-error")[0]
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(browser, WAIT_S).until(lambda _: error.text)
    assert "The key was refused" in error.text
    assert browser.execute_script("return sessionStorage.length") == 0


def test_the_overview_lists_the_robots_with_their_latest_run(
    signed_in: Any, live_app: LiveApp, artifacts_dir: Path
) -> None:
    browser = signed_in
    open_page(browser, live_app.url, "/")
    rows = wait_for(browser, "table#fleet tbody tr", count=5)
    by_robot = {row.get_attribute("data-robot-id"): row for row in rows}
    assert sorted(by_robot) == ["R1", "R2", "R3", "R4", "R5"]
    r1 = by_robot["R1"]
    assert (
        r1.find_element("css selector", "[data-verdict]").get_attribute("data-verdict") == "passed"
    )
    assert "demo-bot" in r1.text and "1.4 mm" in r1.text and "accepted" in r1.text
    assert by_robot["R2"].find_element("css selector", "[data-status]").text == "failed"
    assert by_robot["R3"].find_element("css selector", "[data-status]").text == "running"
    # The key was entered once: a reload keeps it (session storage), no form again.
    open_page(browser, live_app.url, "/")
    assert len(wait_for(browser, "table#fleet tbody tr", count=5)) == 5
    screenshot(browser, artifacts_dir, "overview")


def test_the_robot_page_charts_each_lidar_against_its_tolerance(
    signed_in: Any, live_app: LiveApp, artifacts_dir: Path
) -> None:
    browser = signed_in
    open_page(browser, live_app.url, "/robots/R1")
    charts = wait_for(browser, "#extrinsics svg.chart", count=4)
    for chart in charts:
        # Three runs, three axes: nine points, each drawn with its size (the chart rendered).
        dots = chart.find_elements("css selector", "circle.dot")
        assert len(dots) == 9
        assert chart.size["width"] > 300 and chart.size["height"] > 100
        assert len(chart.find_elements("css selector", "rect.band")) == 1
        assert chart.find_elements("css selector", "circle.dot.failed")
    rear = wait_for(browser, 'article.lidar[data-frame="lidar_rear"]')[0]
    # Drift of the repaired mount since the first accepted calibration, within tolerance.
    assert "Drift since the first accepted calibration" in rear.text
    assert "within tolerance" in rear.text
    assert "limit 10.0 mm" in rear.text
    assert len(browser.find_elements("css selector", "table.runs tbody tr")) == 3
    screenshot(browser, artifacts_dir, "robot")


def test_a_passed_run_shows_its_verdict_checks_and_images(
    signed_in: Any, live_app: LiveApp, artifacts_dir: Path
) -> None:
    browser = signed_in
    run = live_app.fleet.repaired
    open_page(browser, live_app.url, f"/runs/{run}")
    verdict = wait_for(browser, "#verdict [data-verdict]")[0]
    assert verdict.get_attribute("data-verdict") == "passed"
    assert "20.3 mm before" in wait_for(browser, "#metric-error")[0].text
    checks = wait_for(browser, "#checks tbody tr", count=5)
    names = [row.get_attribute("data-check") for row in checks]
    assert names[0] == "metric_error" and "drift_translation:lidar_rear" in names
    images = wait_for(browser, 'img.report-image[data-loaded="true"]', count=3)
    assert [image.get_attribute("data-name") for image in images] == [
        "map-top",
        "map-side",
        "error",
    ]
    for image in images:
        assert browser.execute_script("return arguments[0].naturalWidth", image) >= 800
    stages = wait_for(
        browser, "svg.chart.stages rect.bar", count=len(live_app.fleet.documents[run]["stages"])
    )
    assert stages
    assert len(wait_for(browser, "#downloads button.download", count=5)) == 5
    assert wait_for(browser, 'tr[data-frame="lidar_rear"]')[0].text.count("[") >= 4
    screenshot(browser, artifacts_dir, "run-passed")


def test_a_failed_run_names_its_failed_check(
    signed_in: Any, live_app: LiveApp, artifacts_dir: Path
) -> None:
    browser = signed_in
    open_page(browser, live_app.url, f"/runs/{live_app.fleet.hit}")
    assert wait_for(browser, "#verdict [data-verdict]")[0].get_attribute("data-verdict") == "failed"
    failed = wait_for(browser, "#checks tr.failed-row", count=2)
    assert {row.get_attribute("data-check") for row in failed} == {
        "drift_translation:lidar_rear",
        "drift_rotation:lidar_rear",
    }
    assert "has its mount moved or been hit?" in failed[0].text
    assert wait_for(browser, "#allow-failed")
    assert "last accepted calibration" in wait_for(browser, "#drift")[0].text
    screenshot(browser, artifacts_dir, "run-failed")


def test_a_running_run_shows_its_progress(signed_in: Any, live_app: LiveApp) -> None:
    browser = signed_in
    open_page(browser, live_app.url, f"/runs/{live_app.fleet.running}")
    # The card is redrawn every second while the run is running: read it in one script.
    text, value = browser.execute_script(
        "const card = document.getElementById('progress');"
        "return [card.innerText, card.querySelector('[role=progressbar]')"
        ".getAttribute('aria-valuenow')]"
    )
    assert "Running: optimisation" in text
    assert value == "45"


def test_a_run_that_failed_shows_its_problem(signed_in: Any, live_app: LiveApp) -> None:
    browser = signed_in
    open_page(browser, live_app.url, f"/runs/{live_app.fleet.failed}")
    error = wait_for(browser, "#run-error")[0]
    assert "no stops found in the trajectory" in error.text
