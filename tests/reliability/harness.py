"""What the fault and bad-input tests share: runs whose recordings are really in storage, worker
and API processes that a test can kill with SIGKILL, and the database rows to judge the outcome."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
from sqlalchemy import func, select

from service import repository
from service.db import Database
from service.models import LidarExtrinsic, Result, RunKind
from service.settings import Settings
from service.storage import make_storage
from tests.service.uploads import new_upload
from tests.workers.runs import ROOT, entrypoint_env, run_row, wait_for

QUICK = {
    "optimisation": {
        "max_iterations": 2,
        "coarse_points_per_cloud": None,
        "max_points_per_cloud": 100,
        "normal_neighbours": 10,
    }
}
"""A pipeline config that calibrates the `tiny` scenario in about a second: these tests are about
what happens around the pipeline, not its accuracy."""


def store_run(
    settings: Settings,
    db: Database,
    body: bytes,
    *,
    robot_id: str = "R1",
    config: dict[str, Any] | None = None,
    max_attempts: int = 3,
    kind: RunKind = RunKind.END_OF_LINE,
) -> uuid.UUID:
    """A queued run of `body`, stored and recorded as the upload endpoint does it."""
    run_id = uuid.uuid4()
    key = f"recordings/{robot_id}/{run_id}"
    pending = make_storage(settings).begin_upload(key)
    pending.write(body)
    pending.commit()
    from pipeline.io.formats import detect_format_from_head

    detected = detect_format_from_head(body[:4096])
    assert detected is not None, "the test's recording must pass the upload's format check"
    with db.transaction() as session:
        repository.record_upload(
            session,
            new_upload(
                robot_id,
                run_id=run_id,
                kind=kind,
                body=body,
                format=detected.value,
                storage_key=key,
                config=config,
                max_attempts=max_attempts,
            ),
            create_robot=True,
        )
    return run_id


def stored_results(db: Database, run_id: uuid.UUID) -> tuple[int, int]:
    """(result rows, per-LiDAR extrinsics rows) of the run."""
    with db.session() as session:
        results = session.scalar(
            select(func.count()).select_from(Result).where(Result.run_id == run_id)
        )
        rows = session.scalar(
            select(func.count()).select_from(LidarExtrinsic).where(LidarExtrinsic.run_id == run_id)
        )
    return int(results or 0), int(rows or 0)


def stored_once(db: Database, run_id: uuid.UUID) -> bool:
    """One result, and one extrinsics row per LiDAR it calibrated (none twice)."""
    with db.session() as session:
        results = list(session.scalars(select(Result).where(Result.run_id == run_id)))
        frames = list(
            session.scalars(select(LidarExtrinsic.frame).where(LidarExtrinsic.run_id == run_id))
        )
    if len(results) != 1:
        return False
    calibrated = [
        frame
        for frame, lidar in results[0].document["lidars"].items()
        if lidar.get("calibrated") is not None
    ]
    return sorted(frames) == sorted(calibrated) and len(frames) > 0


def environment(settings: Settings, **extra: str) -> dict[str, str]:
    return entrypoint_env(
        FLEETCAL_DATABASE_URL=settings.resolved_database_url,
        FLEETCAL_STORAGE_URL=settings.resolved_storage_url,
        FLEETCAL_RUN_LEASE_SECONDS=str(settings.run_lease_seconds),
        FLEETCAL_MIGRATE_ON_START="false",
        **extra,
    )


@dataclass
class Process:
    """A `fleetcal` process in its own session: SIGKILL reaches it and its pipeline children."""

    popen: subprocess.Popen[bytes]
    log: Path

    def kill(self) -> None:
        """kill -9 the process group, as an out-of-memory killer or a pulled plug would."""
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.wait(timeout=30)

    def stop(self) -> None:
        if self.popen.poll() is None:
            os.killpg(self.popen.pid, signal.SIGTERM)
            try:
                self.popen.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.kill()

    def output(self) -> str:
        return self.log.read_text(errors="replace")[-4000:]


def start(argv: list[str], env: dict[str, str], log: Path) -> Process:
    with log.open("ab") as sink:
        popen = subprocess.Popen(
            argv,
            env=env,
            cwd=ROOT,
            start_new_session=True,
            stdout=sink,
            stderr=subprocess.STDOUT,
        )
    return Process(popen, log)


@contextmanager
def processes() -> Iterator[list[Process]]:
    """Processes started in the block; whatever is still alive at its end is killed."""
    started: list[Process] = []
    try:
        yield started
    finally:
        for process in started:
            process.kill()


def start_worker(
    settings: Settings, job: str, log: Path, *, concurrency: int = 1, **env: str
) -> Process:
    command = ["fleetcal", "worker", "--concurrency", str(concurrency), "--job", job]
    return start([*command, "--log-level", "info"], environment(settings, **env), log)


def api_argv(port: int) -> list[str]:
    """`fleetcal serve --workers 0`: the API alone."""
    return ["fleetcal", "serve", "--workers", "0", "--port", str(port), "--no-access-log"]


def start_api(
    settings: Settings, log: Path, *, wrap: list[str] | None = None, **env: str
) -> tuple[Process, str]:
    """The API on a free loopback port (its command after `wrap`, if given); waits until ready."""
    port = free_port()
    process = start([*(wrap or []), *api_argv(port)], environment(settings, **env), log)
    url = f"http://127.0.0.1:{port}"
    wait_ready(url, process)
    return process, url


def wait_ready(url: str, process: Process, timeout: float = 120) -> None:
    """Until the API at `url` answers /readyz (failing at once if its process died)."""

    def ready() -> bool:
        assert process.popen.poll() is None, process.output()
        try:
            return httpx.get(f"{url}/readyz", timeout=5).status_code == 200
        except httpx.TransportError:
            return False

    wait_for("the API", ready, timeout=timeout)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


__all__ = ["run_row", "wait_for"]
