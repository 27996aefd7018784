"""Driving the dashboard in the browser tests: waiting for elements and pages, signing in with a
key, screenshots, and files the browser downloaded."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Literal

import httpx

WAIT_S = 30


def wait_for(browser: Any, css: str, count: int = 1) -> list[Any]:
    """The elements matching `css` once there are at least `count` of them."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    def found(driver: Any) -> list[Any] | Literal[False]:
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


def sign_in(browser: Any, base_url: str, key: str) -> None:
    """Enter `key` in the dashboard's form, as a person does, forgetting any key entered before."""
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(f"{base_url}/")
    browser.execute_script("sessionStorage.clear()")
    browser.refresh()
    wait_for(browser, "#api-key")[0].send_keys(key)
    wait_for(browser, "#key-form button")[0].click()
    WebDriverWait(browser, WAIT_S).until(
        lambda driver: driver.execute_script(
            "const a = document.getElementById('app');"
            "return a.dataset.route === '/' && a.dataset.ready === 'true'"
        ),
        "the overview was not drawn after signing in",
    )


def downloaded(folder: Path, name: str) -> Path:
    """The file `name` once the browser has finished saving it into `folder`."""
    path = folder / name
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        if path.is_file() and not list(folder.glob("*.crdownload")):
            return path
        time.sleep(0.1)
    raise AssertionError(f"{name} was not downloaded; the folder has {sorted(folder.iterdir())}")


def api_json(base_url: str, key: str, path: str) -> Any:
    """What the API answers `key` for `path`: the figures the page must show."""
    response = httpx.get(f"{base_url}{path}", headers={"X-API-Key": key})
    assert response.status_code == 200, response.text
    return response.json()
