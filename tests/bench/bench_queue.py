"""The queue on PostgreSQL: N queued runs drained by W worker processes (none lost, none done
twice), throughput, claim latency, and how long an upload waits for an idle worker.

    .venv/bin/python -m tests.bench.bench_queue [--runs 500] [--workers 4] [--pickups 40]

1. Drain: `--runs` runs are queued in one transaction, then `--workers` `fleetcal worker
   --concurrency 1` processes drain them, each attempt running the test job
   `tests.workers.jobs:scripted`, which returns a real `result.json` at once: the figures are the
   queue's (claim, heartbeat, child round trip, result + extrinsics + status in one transaction),
   not the pipeline's. Throughput is runs over the span from the first claim to the last finish,
   from the database's own timestamps. Checked: every run `succeeded`, at its first attempt, with
   exactly one result and one extrinsics row per LiDAR.
2. Claim latency: four claimer threads, each with its own engine as separate workers have, empty a
   backlog through `workers.queue.claim` (SELECT ... FOR UPDATE SKIP LOCKED + UPDATE, one
   transaction); the wall time of each claim.
3. Pick-up: the workers idle, `--pickups` runs are uploaded one by one (0.3 s apart): the time
   from upload (`created_at`) to claim (`started_at`), what a robot waits before its run starts.

Each phase runs in its own scratch database, dropped afterwards.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

import psycopg
from sqlalchemy import func, select

from service.db import Database
from service.models import LidarExtrinsic, Result, Run, RunKind, RunStatus
from service.settings import Settings
from tests.workers.jobs import SCRIPTED
from tests.workers.runs import enqueue_many
from workers import queue

ROOT = Path(__file__).resolve().parents[2]
PG_ADMIN_DSN = os.environ.get(
    "FLEETCAL_TEST_PG_ADMIN_DSN", "postgresql://postgres@127.0.0.1:5432/postgres"
)
LIDARS_PER_RESULT = 2  # the scripted job's result calibrates two of its three LiDARs


@contextlib.contextmanager
def scratch_database() -> Iterator[Settings]:
    """Settings for a new, migrated PostgreSQL database and local storage; both removed after."""
    name = f"fleetcal_bench_{uuid.uuid4().hex[:12]}"
    info = psycopg.conninfo.conninfo_to_dict(PG_ADMIN_DSN)
    url = (
        f"postgresql+psycopg://{info.get('user', 'postgres')}@{info.get('host', '127.0.0.1')}:"
        f"{info.get('port', '5432')}/{name}"
    )
    with (
        psycopg.connect(PG_ADMIN_DSN, autocommit=True) as admin,
        tempfile.TemporaryDirectory(prefix="fleetcal-bench-") as storage,
    ):
        admin.execute(f'CREATE DATABASE "{name}"')
        try:
            settings = Settings(
                database_url=url, storage_url=Path(storage).as_uri(), migrate_on_start=False
            )
            db = Database.from_settings(settings)
            db.upgrade()
            db.dispose()
            yield settings
        finally:
            admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@contextlib.contextmanager
def worker_processes(settings: Settings, count: int) -> Iterator[list[subprocess.Popen[bytes]]]:
    """`count` `fleetcal worker` processes on `settings`, stopped with SIGTERM on leaving."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("FLEETCAL_")}
    env.update(
        FLEETCAL_DATABASE_URL=settings.resolved_database_url,
        FLEETCAL_STORAGE_URL=settings.resolved_storage_url,
        FLEETCAL_MIGRATE_ON_START="false",
        PYTHONPATH=str(ROOT),
    )
    fleetcal = str(Path(sys.executable).parent / "fleetcal")
    command = [
        fleetcal,
        "worker",
        "--concurrency",
        "1",
        "--job",
        SCRIPTED,
        "--log-level",
        "error",
    ]
    processes = [subprocess.Popen(command, env=env, cwd=ROOT) for _ in range(count)]
    try:
        yield processes
    finally:
        for process in processes:
            process.send_signal(signal.SIGTERM)
        for process in processes:
            try:
                process.wait(60)
            except subprocess.TimeoutExpired:
                process.kill()


def count_final(db: Database) -> int:
    with db.session() as session:
        final = (RunStatus.SUCCEEDED, RunStatus.FAILED)
        return int(
            session.scalar(select(func.count()).select_from(Run).where(Run.status.in_(final))) or 0
        )


def wait_until(what: str, predicate: Callable[[], bool], timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        time.sleep(0.1)


@dataclass(frozen=True)
class Drain:
    runs: int
    workers: int
    succeeded: int
    first_attempt: int
    results: int
    extrinsics_rows: int
    seconds: float
    workers_used: int

    @property
    def throughput(self) -> float:
        return self.runs / self.seconds if self.seconds > 0 else float("nan")

    @property
    def lost(self) -> int:
        return self.runs - self.succeeded

    @property
    def duplicated(self) -> int:
        """Runs attempted more than once or with extra rows: each would be work done twice."""
        extra_rows = self.extrinsics_rows - LIDARS_PER_RESULT * self.results
        return (self.runs - self.first_attempt) + (self.results - self.succeeded) + extra_rows


def drain(settings: Settings, runs: int, workers: int, timeout: float = 600) -> Drain:
    """Queue `runs` runs, drain them with `workers` worker processes, and count what happened."""
    db = Database.from_settings(settings)
    try:
        enqueue_many(db, runs, robots=20, kind=RunKind.MAINTENANCE)
        with worker_processes(settings, workers):
            wait_until(f"{runs} runs", lambda: count_final(db) == runs, timeout)
        with db.session() as session:
            rows = session.execute(select(Run.status, Run.attempts)).all()
            span = session.execute(
                select(func.min(Run.started_at), func.max(Run.finished_at))
            ).one()
            results = session.scalar(select(func.count()).select_from(Result)) or 0
            extrinsics = session.scalar(select(func.count()).select_from(LidarExtrinsic)) or 0
            owners = session.scalars(select(Result.document["worker"]["pid"].as_string())).all()
    finally:
        db.dispose()
    return Drain(
        runs=runs,
        workers=workers,
        succeeded=sum(1 for status, _ in rows if status == RunStatus.SUCCEEDED),
        first_attempt=sum(1 for _, attempts in rows if attempts == 1),
        results=int(results),
        extrinsics_rows=int(extrinsics),
        seconds=(span[1] - span[0]).total_seconds() if span[0] and span[1] else float("nan"),
        workers_used=len(set(owners)),
    )


def claim_latencies(settings: Settings, runs: int, claimers: int = 4) -> list[float]:
    setup = Database.from_settings(settings)
    enqueue_many(setup, runs, robots=20)
    setup.dispose()
    latencies: list[float] = []
    lock = threading.Lock()
    start = threading.Barrier(claimers)

    def claimer(index: int) -> None:
        db = Database.from_settings(settings)
        start.wait()
        while True:
            began = time.perf_counter()
            held = queue.claim(db, f"bench-{index}", timedelta(minutes=5))
            elapsed = time.perf_counter() - began
            if held is None:
                break
            with lock:
                latencies.append(elapsed)
        db.dispose()

    threads = [threading.Thread(target=claimer, args=(i,)) for i in range(claimers)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return latencies


def pickup_latencies(settings: Settings, workers: int, pickups: int) -> list[float]:
    db = Database.from_settings(settings)
    try:
        with worker_processes(settings, workers):
            # Let every worker start and go idle before the first upload.
            enqueue_many(db, 1, prefix="warm-up")
            wait_until("the warm-up run", lambda: count_final(db) == 1, 300)
            time.sleep(2)
            for _ in range(pickups):
                enqueue_many(db, 1, prefix="pickup")
                time.sleep(0.3)
            wait_until("the pick-ups", lambda: count_final(db) == pickups + 1, 300)
        with db.session() as session:
            rows = session.execute(
                select(Run.created_at, Run.started_at).where(Run.robot_id == "pickup")
            ).all()
    finally:
        db.dispose()
    return [(started - created).total_seconds() for created, started in rows if started]


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--workers", type=int, default=4)
    parser.add_argument("--pickups", type=int, default=40)
    args = parser.parse_args()

    load = os.getloadavg()
    print(f"CPUs: {os.cpu_count()}, load average before: {load[0]:.1f} {load[1]:.1f}\n")
    with scratch_database() as settings:
        result = drain(settings, args.runs, args.workers)
    print(f"### Drain: {result.runs} queued runs, {result.workers} worker processes (PostgreSQL)\n")
    print(
        "| runs | succeeded | lost | done twice | results | extrinsics rows | workers used "
        "| span s | runs/s |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    print(
        f"| {result.runs} | {result.succeeded} | {result.lost} | {result.duplicated} "
        f"| {result.results} | {result.extrinsics_rows} | {result.workers_used} "
        f"| {result.seconds:.1f} | {result.throughput:.1f} |\n"
    )

    with scratch_database() as settings:
        claims = claim_latencies(settings, args.runs)
    with scratch_database() as settings:
        pickups = pickup_latencies(settings, args.workers, args.pickups)
    print("### Latency\n")
    print("| what | n | median ms | p95 ms | max ms |")
    print("|---|---:|---:|---:|---:|")
    for label, values in (
        ("claim transaction, 4 claimers on a backlog", claims),
        ("upload to claim, idle workers (poll 0.25 s)", pickups),
    ):
        print(
            f"| {label} | {len(values)} | {statistics.median(values) * 1000:.1f} "
            f"| {percentile(values, 0.95) * 1000:.1f} | {max(values) * 1000:.1f} |"
        )
    if result.lost or result.duplicated:
        sys.exit(f"FAILED: {result.lost} runs lost, {result.duplicated} done twice")


if __name__ == "__main__":
    main()
