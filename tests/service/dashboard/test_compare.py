"""Comparing two runs of a robot in headless Chromium (compare.js): per LiDAR the change in
translation and rotation with their units, as the API computed it, both verdicts, the picker,
and the API's refusals in the page."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tests.service.dashboard.browser import api_json, open_page, screenshot, sign_in, wait_for
from tests.service.dashboard.conftest import LiveApp


@pytest.fixture(scope="module")
def signed_in(browser: Any, live_app: LiveApp) -> Any:
    sign_in(browser, live_app.url, live_app.read_key)
    return browser


def number(text: str, unit: str) -> float:
    """The value of a cell such as `+15.0 mm` or `0.802°`, checking its unit."""
    match = re.fullmatch(rf"([+-]?\d+(?:\.\d+)?) ?{unit}", text.strip())
    assert match, (text, unit)
    return float(match[1])


def cells(browser: Any, frame: str) -> dict[str, str]:
    row = wait_for(browser, f'#comparison tr[data-frame="{frame}"]')[0]
    names = ["translation", "delta-x", "delta-y", "delta-z", "rotation"]
    return {name: row.find_element("css selector", f"td.{name}").text for name in names}


def test_each_lidars_change_is_the_apis_with_units(
    signed_in: Any, live_app: LiveApp, artifacts_dir: Path
) -> None:
    browser, fleet = signed_in, live_app.fleet
    route = f"/robots/R1/compare?from={fleet.end_of_line}&to={fleet.hit}"
    open_page(browser, live_app.url, route)
    want = api_json(
        live_app.url,
        live_app.read_key,
        f"/v1/robots/R1/compare?from={fleet.end_of_line}&to={fleet.hit}",
    )
    assert sorted(want["lidars"]) == ["lidar_front", "lidar_rear"]
    for frame, change in want["lidars"].items():
        shown = cells(browser, frame)
        # mm with one decimal from 1 mm up (none below 1 mm: two), degrees with three below 1°.
        assert number(shown["translation"], "mm") == pytest.approx(
            change["translation_m"] * 1000, abs=0.051
        )
        for k, axis in enumerate("xyz"):
            assert number(shown[f"delta-{axis}"], "mm") == pytest.approx(
                change["delta_translation"][k] * 1000, abs=0.051
            )
        assert number(shown["rotation"], "°") == pytest.approx(change["rotation_deg"], abs=5e-4)
    # The hit mount: 15 mm and 0.014 rad (0.802°) off; the reference LiDAR did not move.
    rear = cells(browser, "lidar_rear")
    assert (rear["translation"], rear["rotation"]) == ("15.0 mm", "0.802°")
    assert cells(browser, "lidar_front")["translation"] == "0 mm"
    facts = wait_for(browser, "#comparison dl.facts")[0]
    verdicts = [
        b.get_attribute("data-verdict")
        for b in facts.find_elements("css selector", "[data-verdict]")
    ]
    assert verdicts == ["passed", "failed"]
    assert fleet.end_of_line.hex[:8] in facts.text.replace("-", "")
    screenshot(browser, artifacts_dir, "compare")


def test_the_picker_defaults_to_the_two_newest_and_compares_what_is_chosen(
    signed_in: Any, live_app: LiveApp
) -> None:
    from selenium.webdriver.support.ui import Select

    browser, fleet = signed_in, live_app.fleet
    open_page(browser, live_app.url, "/robots/R1")
    link = wait_for(browser, "#compare-link")[0]
    assert link.get_attribute("href").endswith("#/robots/R1/compare")
    open_page(browser, live_app.url, "/robots/R1/compare")
    assert Select(wait_for(browser, "#compare-from")[0]).first_selected_option.get_attribute(
        "value"
    ) == str(fleet.hit)
    assert Select(wait_for(browser, "#compare-to")[0]).first_selected_option.get_attribute(
        "value"
    ) == str(fleet.repaired)
    # Repaired against hit: the rear mount came back (~13 mm).
    assert number(cells(browser, "lidar_rear")["translation"], "mm") > 10
    Select(wait_for(browser, "#compare-from")[0]).select_by_value(str(fleet.end_of_line))
    browser.execute_script("document.getElementById('app').dataset.ready = 'stale'")
    wait_for(browser, "#compare-form button")[0].click()
    from selenium.webdriver.support.ui import WebDriverWait

    route = f"/robots/R1/compare?from={fleet.end_of_line}&to={fleet.repaired}"
    WebDriverWait(browser, 30).until(
        lambda d: d.execute_script(
            "const a = document.getElementById('app');"
            "return a.dataset.route === arguments[0] && a.dataset.ready === 'true'",
            route,
        )
    )
    want = api_json(
        live_app.url,
        live_app.read_key,
        f"/v1/robots/R1/compare?from={fleet.end_of_line}&to={fleet.repaired}",
    )
    assert number(cells(browser, "lidar_rear")["translation"], "mm") == pytest.approx(
        want["lidars"]["lidar_rear"]["translation_m"] * 1000, abs=0.051
    )


def test_the_apis_refusal_is_shown_beside_the_picker(signed_in: Any, live_app: LiveApp) -> None:
    browser, fleet = signed_in, live_app.fleet
    # A run of another robot: the API's 404, in the page, with the picker still there.
    open_page(browser, live_app.url, f"/robots/R1/compare?from={fleet.hit}&to={fleet.diverged}")
    error = wait_for(browser, "#compare-error")[0]
    assert f"robot 'R1' has no run {fleet.diverged}" in error.text
    assert wait_for(browser, "#compare-form")
    assert "from the address" in wait_for(browser, "#compare-to option")[0].text
    # R5 has a single run with a result: nothing to compare.
    open_page(browser, live_app.url, "/robots/R5/compare")
    assert (
        "needs two runs with a result; robot R5 has 1" in wait_for(browser, "#compare-none")[0].text
    )
