"""Fixtures for the dashboard, report and export tests: a seeded fleet (see `seed`), the app served
by uvicorn on a free loopback port, and headless Chromium driven by Selenium.

Screenshots go to `$FLEETCAL_TEST_ARTIFACTS` (CI keeps that folder), else `tests-artifacts/` at
the repository root.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
import uvicorn

from service import repository
from service.app import create_app
from service.auth import create_key
from service.db import Database
from service.models import Scope
from service.settings import Settings
from service.storage import make_storage
from tests.conftest import unavailable
from tests.service.conftest import Api
from tests.service.dashboard.seed import Fleet, recording_bytes, report_images, seed_fleet

REPO_ROOT = Path(__file__).resolve().parents[3]
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "chrome")
CHROMEDRIVER_NAMES = ("chromedriver", "chromium-driver")


@pytest.fixture(scope="session")
def seed_images() -> dict[str, bytes]:
    return report_images()


@pytest.fixture(scope="session")
def seed_recording(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    return recording_bytes(tmp_path_factory.mktemp("seed"))


@pytest.fixture
def fleet(api: Api, seed_recording: bytes, seed_images: dict[str, bytes]) -> Fleet:
    """The seeded fleet in the `api` fixture's database (SQLite and PostgreSQL)."""
    return seed_fleet(api.services.db, api.services.storage, seed_recording, seed_images)


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    path = Path(os.environ.get("FLEETCAL_TEST_ARTIFACTS", REPO_ROOT / "tests-artifacts"))
    path.mkdir(parents=True, exist_ok=True)
    return path


# -- the app on a real socket ---------------------------------------------------------------------


@dataclass(frozen=True)
class ServedApp:
    url: str
    read_key: str


@dataclass(frozen=True)
class LiveApp(ServedApp):
    fleet: Fleet
    keys: dict[str, str] = field(default_factory=dict)
    """Secrets by `KEY_SCOPES` name."""
    data_dir: Path | None = None


KEY_SCOPES = {
    "read": [Scope.READ],
    "operator": [Scope.READ, Scope.OVERRIDE],  # an operator who accepts and rejects
    "admin": [Scope.ADMIN],
}


def _free_socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(64)
    return sock


FleetApps = Callable[..., contextlib.AbstractContextManager[LiveApp]]


@pytest.fixture(scope="session")
def fleet_apps(
    tmp_path_factory: pytest.TempPathFactory,
    seed_recording: bytes,
    seed_images: dict[str, bytes],
) -> FleetApps:
    """Makes served apps of the seeded fleet, `with fleet_apps(name[, before_seed]) as app:`;
    tests that change the fleet (accept, reject) use one of their own."""

    def make(
        name: str, before_seed: Callable[[Database], None] | None = None
    ) -> contextlib.AbstractContextManager[LiveApp]:
        folder = tmp_path_factory.mktemp(name)
        return seeded_app(folder, seed_recording, seed_images, before_seed)

    return make


@pytest.fixture(scope="session")
def live_app(fleet_apps: FleetApps) -> Iterator[LiveApp]:
    """The app (SQLite, local storage) served by uvicorn from a thread, with the fleet seeded; for
    tests that only read it."""
    with fleet_apps("live") as app:
        yield app


@contextlib.contextmanager
def seeded_app(
    data_dir: Path,
    recording: bytes,
    images: dict[str, bytes],
    before_seed: Callable[[Database], None] | None = None,
) -> Iterator[LiveApp]:
    """The seeded fleet in a new SQLite database under `data_dir`, served, with a key of each of
    `KEY_SCOPES`; `before_seed` runs first (webhooks registered then get the fleet's events)."""
    settings = Settings(data_dir=data_dir)
    db = Database.from_settings(settings)
    db.upgrade()
    if before_seed is not None:
        before_seed(db)
    fleet = seed_fleet(db, make_storage(settings), recording, images)
    with db.transaction() as session:
        keys = {
            name: create_key(session, scopes, name=f"dashboard {name}").secret
            for name, scopes in KEY_SCOPES.items()
        }
    db.dispose()
    with serving(settings) as url:
        yield LiveApp(url=url, read_key=keys["read"], fleet=fleet, keys=keys, data_dir=data_dir)


@contextlib.contextmanager
def serving(settings: Settings) -> Iterator[str]:
    """The app for `settings` served by uvicorn from a thread; yields its base URL."""
    sock = _free_socket()
    server = uvicorn.Server(
        uvicorn.Config(create_app(settings), log_level="warning", lifespan="on")
    )
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    while not server.started:
        if not thread.is_alive():
            pytest.fail("the app did not start; see the log")
        time.sleep(0.05)
    url = f"http://127.0.0.1:{sock.getsockname()[1]}"
    assert httpx.get(f"{url}/healthz").status_code == 200
    try:
        yield url
    finally:
        server.should_exit = True
        thread.join(timeout=30)
        sock.close()


# -- the browser ----------------------------------------------------------------------------------


def _which(names: tuple[str, ...], env: str) -> str | None:
    if os.environ.get(env):
        return os.environ[env]
    return next((found for name in names if (found := shutil.which(name))), None)


@pytest.fixture(scope="module")
def download_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where the module's browser saves downloads."""
    return tmp_path_factory.mktemp("downloads")


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory, download_dir: Path) -> Iterator[Any]:
    """Headless Chromium through chromedriver, saving downloads in `download_dir` without asking;
    skipped (with the reason) only if not installed, and failed then under CI=true."""
    chromium = _which(CHROMIUM_NAMES, "FLEETCAL_CHROMIUM")
    driver_path = _which(CHROMEDRIVER_NAMES, "FLEETCAL_CHROMEDRIVER")
    if chromium is None or driver_path is None:
        unavailable(
            "headless Chromium is not installed (Debian: apt-get install chromium chromium-driver; "
            "or set FLEETCAL_CHROMIUM and FLEETCAL_CHROMEDRIVER); CI installs it"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for argument in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        "--window-size=1400,1000",
        f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}",
    ):
        options.add_argument(argument)
    # The console log: a resource the page asks for and does not get (favicon) shows there.
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    options.add_experimental_option(
        "prefs",
        {"download.default_directory": str(download_dir), "download.prompt_for_download": False},
    )
    driver = webdriver.Chrome(service=Service(executable_path=driver_path), options=options)
    driver.execute_cdp_cmd(
        "Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(download_dir)}
    )
    driver.set_page_load_timeout(60)
    try:
        yield driver
    finally:
        driver.quit()


BIG_FLEET = 250
"""Robots of `big_fleet_app`: more than the overview's first page (200)."""


@pytest.fixture(scope="session")
def big_fleet_app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServedApp]:
    """The app with `BIG_FLEET` robots that never uploaded, and no runs."""
    settings = Settings(data_dir=tmp_path_factory.mktemp("big-fleet"))
    db = Database.from_settings(settings)
    db.upgrade()
    with db.transaction() as session:
        for index in range(BIG_FLEET):
            repository.put_robot(session, f"B{index:04d}", model="demo-bot", metadata={})
        read_key = create_key(session, [Scope.READ], name="dashboard test").secret
    db.dispose()
    with serving(settings) as url:
        yield ServedApp(url=url, read_key=read_key)
