"""A real `fleetcal serve` in a child process (so a test can SIGKILL it and start it again on the
same port and data), with an admin key and an upload key for robot `ROBOT` made beforehand."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest

from service.auth import create_key
from service.db import Database
from service.models import Scope
from service.settings import Settings

ROBOT = "R7"
START_TIMEOUT_S = 90


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@dataclass
class Served:
    data_dir: Path
    port: int
    workers: int
    admin_key: str
    upload_key: str
    process: subprocess.Popen[bytes] | None = field(default=None)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> None:
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
        self.process = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "from workers.cli import main; main()",
                "serve",
                "--data-dir",
                str(self.data_dir),
                "--port",
                str(self.port),
                "--workers",
                str(self.workers),
                "--no-access-log",
                "--log-level",
                "warning",
            ],
            env=env,
            stdout=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                pytest.fail(f"fleetcal serve exited with {self.process.returncode}")
            try:
                if httpx.get(f"{self.url}/healthz", timeout=1).status_code == 200:
                    return
            except httpx.TransportError:
                time.sleep(0.1)
        pytest.fail("fleetcal serve did not answer /healthz in time")

    def kill(self) -> None:
        assert self.process is not None
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=30)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.kill()

    def runs(self) -> list[dict[str, object]]:
        response = httpx.get(
            f"{self.url}/v1/runs",
            params={"robot_id": ROBOT},
            headers={"X-API-Key": self.admin_key},
        )
        response.raise_for_status()
        items: list[dict[str, object]] = response.json()["items"]
        return items


def prepared(data_dir: Path, workers: int) -> Served:
    db = Database.from_settings(Settings(data_dir=data_dir))
    db.upgrade()
    with db.transaction() as session:
        admin = create_key(session, [Scope.ADMIN], name="client tests").secret
        upload = create_key(session, [Scope.UPLOAD], robot_id=ROBOT, name="robot").secret
    db.dispose()
    return Served(data_dir, free_port(), workers, admin, upload)


@pytest.fixture
def api_only(tmp_path: Path) -> Iterator[Served]:
    """`fleetcal serve --workers 0`: runs stay queued, so the test sees each upload's run."""
    served = prepared(tmp_path / "data", workers=0)
    served.start()
    try:
        yield served
    finally:
        served.stop()
