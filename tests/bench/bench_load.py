"""Load: many robots upload small recordings at once while workers calibrate them. Every run must
be accounted for (one per upload, none lost, none duplicated, each stored once); the figures are
throughput and the latency a robot sees for its upload and for its status polls.

    .venv/bin/python -m tests.bench.bench_load [--robots 50] [--workers 4] [--job pipeline|scripted]
                                               [--databases postgresql,sqlite]

- PostgreSQL, distributed: the API (`fleetcal serve --workers 0`) and `--workers` separate
  `fleetcal worker --concurrency 1` processes on a scratch database.
- SQLite, embedded: `fleetcal serve --workers N`, the API and N pipeline processes in one process.

Each robot (a thread with its own upload key, bound to its robot) uploads the `tiny` scenario
(1.3 MB, a tar of its ROS 2 bag) with an Idempotency-Key, sends the same upload again as a robot
retrying after a lost answer would (it must get the same run back), then polls its run every
0.5 s until it ends. `--job pipeline` (default) runs the real calibration with a quick optimisation
(two iterations: the figures are the service's, not the optimiser's); `--job scripted` runs the
test job that returns a result at once (the API and queue alone).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
from sqlalchemy import func, select

from service.auth import create_key
from service.db import Database
from service.models import LidarExtrinsic, Result, Run, RunStatus, Scope
from service.settings import Settings
from tests.bench.bench_queue import scratch_database
from tests.reliability.harness import QUICK, environment, free_port, processes, start, wait_ready
from tests.workers.jobs import SCRIPTED
from workers.worker import CALIBRATE_JOB

POLL_S = 0.5
FINAL = ("succeeded", "failed")


def tiny_upload() -> bytes:
    from pipeline.synth import write_recording
    from pipeline.synth.recording import archive_recording

    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "synth"
        write_recording("tiny", out, seed=0)
        return archive_recording(out, Path(scratch) / "recording.tar").read_bytes()


@dataclass
class Robot:
    """One robot's session: what it uploaded and what it saw."""

    robot_id: str
    key: str
    run_id: str | None = None
    replayed_id: str | None = None
    upload_s: list[float] = field(default_factory=list)
    status_s: list[float] = field(default_factory=list)
    final: str | None = None
    errors: list[str] = field(default_factory=list)

    def work(self, url: str, body: bytes, config: str, start: threading.Event) -> None:
        headers = {
            "X-API-Key": self.key,
            "Idempotency-Key": str(uuid.uuid4()),
            "X-Fleetcal-Config": config,
        }
        path = f"/v1/robots/{self.robot_id}/runs?kind=end_of_line"
        with httpx.Client(base_url=url, timeout=300) as client:
            start.wait()
            try:
                for attempt in range(2):  # the upload, then the same again (a retry)
                    began = time.perf_counter()
                    response = client.post(path, content=body, headers=headers)
                    self.upload_s.append(time.perf_counter() - began)
                    if response.status_code != 202:
                        self.errors.append(f"upload {response.status_code}: {response.text[:200]}")
                        return
                    if attempt == 0:
                        self.run_id = response.json()["id"]
                    else:
                        self.replayed_id = response.json()["id"]
                while True:
                    began = time.perf_counter()
                    response = client.get(f"/v1/runs/{self.run_id}", headers=headers)
                    self.status_s.append(time.perf_counter() - began)
                    if response.status_code != 200:
                        self.errors.append(f"status {response.status_code}: {response.text[:200]}")
                        return
                    if response.json()["status"] in FINAL:
                        self.final = response.json()["status"]
                        return
                    time.sleep(POLL_S)
            except httpx.HTTPError as err:
                self.errors.append(f"{type(err).__name__}: {err}")


@dataclass
class Outcome:
    database: str
    robots: list[Robot]
    wall_s: float
    runs: int = 0
    results: int = 0
    stored_twice: int = 0
    succeeded: int = 0
    failed: int = 0
    retried: int = 0
    span_s: float = 0.0
    upload_to_end_s: list[float] = field(default_factory=list)

    @property
    def uploads(self) -> int:
        return len(self.robots)

    @property
    def lost(self) -> int:
        """Uploads without a run, and runs that never ended."""
        ids = {r.run_id for r in self.robots if r.run_id}
        return self.uploads - len(ids) + (self.runs - self.succeeded - self.failed)

    @property
    def duplicated(self) -> int:
        """Runs beyond one per upload (a replay that made a second run), and results twice."""
        replays = sum(r.replayed_id != r.run_id for r in self.robots)
        return max(self.runs - self.uploads, 0) + replays + self.stored_twice


def account(db: Database, outcome: Outcome) -> None:
    """Judge the outcome from the database itself, not from what the robots saw."""
    with db.session() as session:
        runs = list(session.scalars(select(Run)))
        per_run = dict(
            session.execute(select(Result.run_id, func.count()).group_by(Result.run_id)).all()
        )
        frames = dict(
            session.execute(
                select(LidarExtrinsic.run_id, func.count()).group_by(LidarExtrinsic.run_id)
            ).all()
        )
        documents: dict[uuid.UUID, dict[str, Any]] = {
            run_id: document
            for run_id, document in session.execute(select(Result.run_id, Result.document))
        }
    outcome.runs = len(runs)
    outcome.results = sum(per_run.values())
    outcome.succeeded = sum(r.status == RunStatus.SUCCEEDED for r in runs)
    outcome.failed = sum(r.status == RunStatus.FAILED for r in runs)
    outcome.retried = sum(r.attempts > 1 for r in runs)
    for run in runs:
        calibrated = len(
            [
                lidar
                for lidar in (documents.get(run.id) or {}).get("lidars", {}).values()
                if lidar.get("calibrated") is not None
            ]
        )
        if per_run.get(run.id, 0) > 1 or frames.get(run.id, 0) != calibrated:
            outcome.stored_twice += 1
        if run.status == RunStatus.SUCCEEDED and per_run.get(run.id) != 1:
            outcome.stored_twice += 1
    ended = [(r.created_at, r.finished_at) for r in runs if r.finished_at is not None]
    if ended:
        first = min(created for created, _ in ended)
        outcome.span_s = (max(finished for _, finished in ended) - first).total_seconds()
        outcome.upload_to_end_s = [(end - created).total_seconds() for created, end in ended]


def robots_for(db: Database, count: int) -> list[Robot]:
    robots = []
    with db.transaction() as session:
        for index in range(count):
            robot_id = f"LOAD{index:03d}"
            key = create_key(session, [Scope.UPLOAD], robot_id=robot_id).secret
            robots.append(Robot(robot_id, key))
        create_key(session, [Scope.ADMIN], name="keeps the first start from making one")
    return robots


def drive(url: str, robots: list[Robot], body: bytes, config: str) -> float:
    start = threading.Event()
    threads = [
        threading.Thread(target=robot.work, args=(url, body, config, start), daemon=True)
        for robot in robots
    ]
    for thread in threads:
        thread.start()
    began = time.perf_counter()
    start.set()
    for thread in threads:
        thread.join()
    return time.perf_counter() - began


def run_load(
    database: str, settings: Settings, args: argparse.Namespace, body: bytes, logs: Path
) -> Outcome:
    db = Database.from_settings(settings)
    db.upgrade()
    robots = robots_for(db, args.robots)
    job = SCRIPTED if args.job == "scripted" else CALIBRATE_JOB
    config = json.dumps(QUICK if args.job == "pipeline" else {})
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = environment(settings, FLEETCAL_MAX_UPLOAD_BYTES=str(64 * 2**20))
    serve = ["fleetcal", "serve", "--port", str(port), "--no-access-log", "--log-level", "warning"]
    with processes() as started:
        if database == "postgresql":
            started.append(start([*serve, "--workers", "0"], env, logs / "api.log"))
            for index in range(args.workers):
                worker = ["fleetcal", "worker", "--concurrency", "1", "--job", job]
                log = logs / f"worker-{index}.log"
                started.append(start([*worker, "--log-level", "warning"], env, log))
        else:
            # The embedded service runs the real job; --job scripted is for PostgreSQL only.
            started.append(start([*serve, "--workers", str(args.workers)], env, logs / "api.log"))
        wait_ready(url, started[0], timeout=180)
        wall = drive(url, robots, body, config)
        for process in started:
            process.stop()
    outcome = Outcome(database, robots, wall)
    account(db, outcome)
    db.dispose()
    return outcome


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    if len(values) == 1:
        return values[0]
    return statistics.quantiles(values, n=100, method="inclusive")[int(q) - 1]


def report(outcomes: list[Outcome], args: argparse.Namespace) -> None:
    print(
        f"\n{args.robots} robots at once, one upload each (and one replay), {args.workers} "
        f"workers, job: {args.job}\n"
    )
    print(
        "| database | uploads | runs | lost | duplicated | succeeded | failed | retried "
        "| runs/s | upload p50 / p95 (s) | status p50 / p95 (s) | upload -> end p50 / p95 (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for o in outcomes:
        uploads = [r.upload_s[0] for r in o.robots if r.upload_s]
        statuses = [s for r in o.robots for s in r.status_s]
        rate = o.runs / o.span_s if o.span_s else float("nan")
        print(
            f"| {o.database} | {o.uploads} | {o.runs} | {o.lost} | {o.duplicated} "
            f"| {o.succeeded} | {o.failed} | {o.retried} | {rate:.2f} "
            f"| {percentile(uploads, 50):.3f} / {percentile(uploads, 95):.3f} "
            f"| {percentile(statuses, 50):.3f} / {percentile(statuses, 95):.3f} "
            f"| {percentile(o.upload_to_end_s, 50):.1f} / {percentile(o.upload_to_end_s, 95):.1f} |"
        )
    errors = [
        f"{o.database} {r.robot_id}: {e}" for o in outcomes for r in o.robots for e in r.errors
    ]
    if errors:
        print("\nErrors seen by robots:\n" + "\n".join(f"- {e}" for e in errors[:20]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--workers", type=int, default=4)
    parser.add_argument("--job", choices=["pipeline", "scripted"], default="pipeline")
    parser.add_argument("--databases", default="postgresql,sqlite")
    args = parser.parse_args()
    body = tiny_upload()
    outcomes = []
    with tempfile.TemporaryDirectory(prefix="fleetcal-load-") as scratch:
        for database in args.databases.split(","):
            logs = Path(scratch) / database
            logs.mkdir()
            if database == "postgresql":
                with scratch_database() as settings:
                    outcomes.append(run_load(database, settings, args, body, logs))
            else:
                settings = Settings(data_dir=Path(scratch) / "sqlite-data")
                outcomes.append(run_load(database, settings, args, body, logs))
    report(outcomes, args)
    if any(o.lost or o.duplicated for o in outcomes):
        raise SystemExit("runs were lost or duplicated")


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        main()
