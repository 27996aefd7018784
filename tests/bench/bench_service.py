"""Service benchmarks: a 1 GB upload over loopback (throughput, server memory growth), and query
latency with 100,000 runs (a robot's history, filtered pages of runs) on SQLite and PostgreSQL.

    .venv/bin/python -m tests.bench.bench_service [--upload-mb 1024] [--repeat 3]
        [--runs 100000] [--robots 500] [--requests 200] [--skip-upload] [--skip-postgres]

The API runs as a real uvicorn server in its own process (as `fleetcal serve` would), the client
in this one. Upload: the body goes out in 1 MiB writes with Content-Length and X-Content-SHA256;
throughput is size over the request's wall time (fsync of the stored file included), with the
server's and client's CPU time beside it (a loaded machine blurs wall time, not CPU time); memory
growth is the server's peak RSS during the upload (VmHWM, reset just before) minus its RSS before.
uvicorn uses httptools and uvloop when installed (`uvicorn[standard]`); h11 alone parses bodies at
about a third of the speed. Queries:
the database is seeded directly (bulk inserts: runs, results with a realistic result.json, two
extrinsics rows per result), then each query is timed end to end over HTTP; p50/p95 over
`--requests` calls on random robots, with the server's CPU time per request (what the query costs
whatever the machine's load). Prints markdown tables; the load average is printed too.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import http.client
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from service.db import Database
    from service.models import RunKind, RunStatus

MIB = 1024 * 1024
MCAP_MAGIC = b"\x89MCAP0\r\n"
PG_ADMIN_DSN = os.environ.get(
    "FLEETCAL_TEST_PG_ADMIN_DSN", "postgresql://postgres@127.0.0.1:5432/postgres"
)

_SERVER = """
import sys, uvicorn
from service.app import create_app
from service.settings import Settings
uvicorn.run(create_app(Settings()), host="127.0.0.1", port=int(sys.argv[1]), log_level="warning")
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@dataclass
class Server:
    process: subprocess.Popen[bytes]
    port: int

    def rss_kib(self, field: str = "VmRSS") -> int:
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
        raise RuntimeError(f"no {field} for pid {self.process.pid}")

    def cpu_seconds(self) -> float:
        fields = Path(f"/proc/{self.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def reset_peak(self) -> None:
        # Writing 5 to clear_refs resets VmHWM to the current RSS (Linux >= 4.0).
        Path(f"/proc/{self.process.pid}/clear_refs").write_text("5")

    def connection(self) -> http.client.HTTPConnection:
        return http.client.HTTPConnection("127.0.0.1", self.port, timeout=600)


@contextlib.contextmanager
def server(env: dict[str, str]) -> Iterator[Server]:
    port = _free_port()
    process = subprocess.Popen(
        [sys.executable, "-c", _SERVER, str(port)], env={**os.environ, **env}
    )
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                connection = http.client.HTTPConnection("127.0.0.1", port, timeout=2)
                connection.request("GET", "/readyz")
                if connection.getresponse().status == 200:
                    break
            except OSError:
                pass
            if time.monotonic() > deadline or process.poll() is not None:
                raise RuntimeError("the API server did not become ready")
            time.sleep(0.2)
        yield Server(process, port)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(20)
        except subprocess.TimeoutExpired:
            process.kill()


def _admin_key(env: dict[str, str]) -> str:
    from service.auth import create_key
    from service.db import Database
    from service.models import Scope
    from service.settings import Settings

    settings = Settings.model_validate(
        {k.removeprefix("FLEETCAL_").lower(): v for k, v in env.items()}
    )
    db = Database.from_settings(settings)
    db.upgrade()
    with db.transaction() as session:
        secret = create_key(session, [Scope.ADMIN]).secret
    db.dispose()
    return secret


# -- upload ----------------------------------------------------------------------------------------


def bench_upload(size_mb: int, workdir: Path, repeat: int) -> list[dict[str, str]]:
    env = {
        "FLEETCAL_DATA_DIR": str(workdir / "upload"),
        "FLEETCAL_MAX_UPLOAD_BYTES": str(4 * size_mb * MIB),
    }
    key = _admin_key(env)
    upload = _Upload.random(size_mb)
    rows = []
    with server(env) as api:
        # Warm up (imports, first connection), then measure from a settled RSS.
        warm = api.connection()
        warm.request(
            "POST",
            "/v1/robots/warmup/runs?kind=end_of_line",
            body=upload.first,
            headers={"X-API-Key": key},
        )
        warm.getresponse().read()
        for attempt in range(repeat):
            time.sleep(0.5)
            rows.append({"upload": f"#{attempt + 1}", **_time_upload(api, key, upload)})
    return rows


@dataclass(frozen=True)
class _Upload:
    """A recording's body of `count` MiB: `first` (MCAP's magic, then random bytes), then
    `count - 1` times the same random MiB `rest`, sent one MiB per write."""

    first: bytes
    rest: bytes
    count: int
    sha256: str

    @classmethod
    def random(cls, size_mb: int) -> _Upload:
        first = MCAP_MAGIC + os.urandom(MIB - len(MCAP_MAGIC))
        rest = os.urandom(MIB)
        digest = hashlib.sha256(first)
        for _ in range(size_mb - 1):
            digest.update(rest)
        return cls(first, rest, size_mb, digest.hexdigest())

    @property
    def size(self) -> int:
        return self.count * MIB

    def body(self) -> Iterator[bytes]:
        yield self.first
        for _ in range(self.count - 1):
            yield self.rest


def _time_upload(api: Server, key: str, upload: _Upload) -> dict[str, str]:
    """One upload's wall time, throughput, server and client CPU time, and the server's peak
    RSS growth over its RSS before."""
    rss_before = api.rss_kib()
    api.reset_peak()
    cpu_before, client_before = api.cpu_seconds(), time.process_time()
    connection = api.connection()
    started = time.perf_counter()
    connection.request(
        "POST",
        "/v1/robots/R1/runs?kind=end_of_line",
        body=upload.body(),
        headers={
            "X-API-Key": key,
            "Content-Length": str(upload.size),
            "X-Content-SHA256": upload.sha256,
            "Content-Type": "application/octet-stream",
        },
    )
    response = connection.getresponse()
    text = response.read()
    seconds = time.perf_counter() - started
    peak = api.rss_kib("VmHWM")
    server_cpu = api.cpu_seconds() - cpu_before
    client_cpu = time.process_time() - client_before
    if response.status != 202:
        raise RuntimeError(f"upload failed: {response.status} {text[:500]!r}")
    total = upload.size
    return {
        "size": f"{total / 1e9:.2f} GB",
        "seconds": f"{seconds:.2f}",
        "throughput": f"{total / seconds / 1e6:.0f} MB/s",
        "server CPU": f"{server_cpu:.2f} s",
        "client CPU": f"{client_cpu:.2f} s",
        "server RSS before": f"{rss_before / 1024:.0f} MiB",
        "server peak RSS growth": f"{(peak - rss_before) / 1024:.1f} MiB",
    }


# -- queries ---------------------------------------------------------------------------------------


def _document(rear_x: float, passed: bool, final: float) -> dict[str, object]:
    from tests.service.documents import result_document

    return result_document(passed=passed, final=final, rear_x=rear_x)


SEED_START = datetime(2025, 1, 1, tzinfo=UTC)
SEED_SPAN_S = timedelta(days=365).total_seconds()
SEED_BATCH = 5000
"""Runs per bulk insert."""


def seed(database_url: str, *, runs: int, robots: int, seed_value: int = 7) -> list[str]:
    """Insert `runs` runs spread over `robots` robots, as a year of a fleet's activity."""
    from service.db import Database
    from service.settings import Settings

    rng = random.Random(seed_value)
    db = Database.from_settings(Settings(database_url=database_url))
    db.upgrade()
    robot_ids = [f"AMR-{i:05d}" for i in range(robots)]
    now = datetime.now(UTC)
    _insert_robots(db, robot_ids)
    rows = _SeedRows()
    for index in range(runs):
        rows.draw_run(rng, robot_ids[index % robots], now)
        if len(rows.runs) >= SEED_BATCH:
            rows.flush(db)
    rows.flush(db)
    _analyze(db)
    db.dispose()
    return robot_ids


def _insert_robots(db: Database, robot_ids: list[str]) -> None:
    from sqlalchemy import insert

    from service.models import Robot

    with db.transaction() as session:
        session.execute(
            insert(Robot),
            [
                {
                    "id": r,
                    "model": f"mk{i % 3 + 1}",
                    "meta": {"site": f"site-{i % 7}"},
                    "created_at": SEED_START,
                    "updated_at": SEED_START,
                }
                for i, r in enumerate(robot_ids)
            ],
        )


@dataclass
class _SeedRows:
    """Rows waiting for a bulk insert: runs, the results of those that succeeded, and two
    extrinsics rows per result."""

    runs: list[dict[str, object]] = field(default_factory=list)
    results: list[dict[str, object]] = field(default_factory=list)
    extrinsics: list[dict[str, object]] = field(default_factory=list)

    def draw_run(self, rng: random.Random, robot: str, now: datetime) -> None:
        """A run of `robot` at a random time of the year: 90 % succeeded, 5 % failed, 4 %
        queued, 1 % running; 80 % maintenance runs. One that succeeded has a result."""
        from service.models import RunKind, RunStatus

        created = SEED_START + timedelta(seconds=rng.random() * SEED_SPAN_S)
        draw = rng.random()
        status = (
            RunStatus.SUCCEEDED
            if draw < 0.9
            else RunStatus.FAILED
            if draw < 0.95
            else RunStatus.QUEUED
            if draw < 0.99
            else RunStatus.RUNNING
        )
        kind = RunKind.MAINTENANCE if rng.random() < 0.8 else RunKind.END_OF_LINE
        run_id = uuid.uuid4()
        self.runs.append(_run_row(run_id, robot, kind, status, created, now))
        if status == RunStatus.SUCCEEDED:
            final = abs(rng.gauss(0.0015, 0.001))
            rear_x = -0.41 + rng.gauss(0, 0.002)
            self._add_result(run_id, robot, created, final, rear_x)

    def _add_result(
        self, run_id: uuid.UUID, robot: str, created: datetime, final: float, rear_x: float
    ) -> None:
        """The result (passed below 4 mm, accepted as it passed: no operator overrode it) and
        its two LiDARs' extrinsics."""
        passed = final < 0.004
        self.results.append(
            {
                "run_id": run_id,
                "robot_id": robot,
                "document": _document(rear_x, passed, final),
                "passed": passed,
                "accepted": passed,
                "metric_error_initial": 0.021,
                "metric_error_final": final,
                "pipeline_version": "0.1.0",
                "config_hash": "sha256:" + "ab" * 32,
                "measured_at": created,
                "created_at": created,
            }
        )
        for frame, x, is_reference in (
            ("lidar_front", 0.45, True),
            ("lidar_rear", rear_x, False),
        ):
            self.extrinsics.append(
                {
                    "run_id": run_id,
                    "robot_id": robot,
                    "frame": frame,
                    "measured_at": created,
                    "passed": passed,
                    "accepted": passed,
                    "is_reference": is_reference,
                    "tx": x,
                    "ty": 0.0,
                    "tz": 0.62,
                    "qx": 0.0,
                    "qy": 0.0,
                    "qz": 0.0,
                    "qw": 1.0,
                    "stddev": None,
                }
            )

    def flush(self, db: Database) -> None:
        from sqlalchemy import insert

        from service.models import LidarExtrinsic, Result, Run

        with db.transaction() as session:
            if self.runs:
                session.execute(insert(Run), self.runs)
            if self.results:
                session.execute(insert(Result), self.results)
            if self.extrinsics:
                session.execute(insert(LidarExtrinsic), self.extrinsics)
        self.runs.clear()
        self.results.clear()
        self.extrinsics.clear()


def _run_row(
    run_id: uuid.UUID,
    robot: str,
    kind: RunKind,
    status: RunStatus,
    created: datetime,
    now: datetime,
) -> dict[str, object]:
    """A run as the API stores it, uploaded at `created` (a 300 MiB MCAP recording); one that
    ended took 40 s, one that failed has no LiDAR data."""
    from service.models import RunStatus

    return {
        "id": run_id,
        "robot_id": robot,
        "kind": kind,
        "status": status,
        "upload_size": 300 * MIB,
        "upload_sha256": "0" * 64,
        "upload_format": "mcap",
        "storage_key": f"recordings/{robot}/{run_id}",
        "idempotency_key": None,
        "config": None,
        "attempts": 1,
        "max_attempts": 3,
        "available_at": created,
        "created_at": created,
        "updated_at": now,
        "started_at": created if status != RunStatus.QUEUED else None,
        "finished_at": created + timedelta(seconds=40)
        if status in (RunStatus.SUCCEEDED, RunStatus.FAILED)
        else None,
        "error": {
            "type": "urn:fleetcal:problem:no-lidar-data",
            "title": "No LiDAR data",
            "status": 422,
            "detail": "no PointCloud2 topic",
        }
        if status == RunStatus.FAILED
        else None,
    }


def _analyze(db: Database) -> None:
    """Statistics for the query planner, as a database that has lived a year would have."""
    if db.engine.dialect.name == "postgresql":
        with db.engine.connect() as connection:
            connection.exec_driver_sql("ANALYZE")
            connection.commit()
    else:
        with db.engine.connect() as connection:
            connection.exec_driver_sql("ANALYZE")


QUERIES = {
    "robot history (all LiDARs)": "/v1/robots/{robot}/history",
    "robot history (one LiDAR, accepted)": "/v1/robots/{robot}/history?frame=lidar_rear"
    "&passed=true",
    "robot's runs, page of 50": "/v1/runs?robot_id={robot}",
    "runs: status=failed, page of 50": "/v1/runs?status=failed",
    "runs: passed=true, kind=maintenance": "/v1/runs?passed=true&kind=maintenance",
    "runs: robot + passed=false": "/v1/runs?robot_id={robot}&passed=false",
    "runs: since 30 days, page 2 by cursor": "/v1/runs?since=2025-12-01T00:00:00Z&cursor={cursor}",
    "latest calibration": "/v1/robots/{robot}/calibration",
}


def bench_queries(
    label: str, env: dict[str, str], robots: list[str], requests: int
) -> list[dict[str, str]]:
    import json

    key = _admin_key(env)
    rng = random.Random(11)
    rows = []
    with server(env) as api:
        connection = api.connection()

        def get(path: str) -> tuple[float, bytes]:
            started = time.perf_counter()
            connection.request("GET", path, headers={"X-API-Key": key})
            response = connection.getresponse()
            body = response.read()
            elapsed = time.perf_counter() - started
            if response.status != 200:
                raise RuntimeError(f"{path}: {response.status} {body[:300]!r}")
            return elapsed, body

        first_page = json.loads(get("/v1/runs?since=2025-12-01T00:00:00Z")[1])
        cursor = first_page["next_cursor"]
        for name, template in QUERIES.items():
            timings, items = [], []
            for _ in range(10):  # warm-up calls are not counted
                get(template.format(robot=rng.choice(robots), cursor=cursor))
            cpu_before = api.cpu_seconds()
            for _ in range(requests):
                path = template.format(robot=rng.choice(robots), cursor=cursor)
                elapsed, body = get(path)
                timings.append(elapsed * 1000)
                items.append(len(json.loads(body).get("items", [1])))
            server_cpu_ms = (api.cpu_seconds() - cpu_before) * 1000 / requests
            timings.sort()
            rows.append(
                {
                    "database": label,
                    "query": name,
                    "items/page": f"{statistics.mean(items):.0f}",
                    "p50 ms": f"{timings[len(timings) // 2]:.1f}",
                    "p95 ms": f"{timings[int(len(timings) * 0.95) - 1]:.1f}",
                    "max ms": f"{timings[-1]:.1f}",
                    "server CPU ms/req": f"{server_cpu_ms:.1f}",
                }
            )
    return rows


@contextlib.contextmanager
def postgres_database() -> Iterator[str]:
    import psycopg

    admin = psycopg.connect(PG_ADMIN_DSN, autocommit=True, connect_timeout=3)
    name = f"fleetcal_bench_{uuid.uuid4().hex[:8]}"
    admin.execute(f'CREATE DATABASE "{name}"')
    info = psycopg.conninfo.conninfo_to_dict(PG_ADMIN_DSN)
    try:
        yield (
            f"postgresql+psycopg://{info.get('user', 'postgres')}@{info.get('host', '127.0.0.1')}"
            f":{info.get('port', '5432')}/{name}"
        )
    finally:
        admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
        admin.close()


def table(rows: list[dict[str, str]]) -> str:
    columns = list(rows[0])
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(row[c] for c in columns) + " |" for row in rows]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--upload-mb", type=int, default=1024)
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--robots", type=int, default=500)
    parser.add_argument("--requests", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=3, help="uploads to time")
    parser.add_argument("--skip-postgres", action="store_true")
    parser.add_argument("--skip-upload", action="store_true")
    args = parser.parse_args()

    import timeit

    # How fast this machine runs Python now (about 0.1 ms on an idle desktop core of 2024).
    speed = min(timeit.repeat("sum(range(10000))", number=200, repeat=5)) / 200 * 1000
    print(
        f"load average: {' '.join(f'{x:.1f}' for x in os.getloadavg())}, "
        f"{os.cpu_count()} CPUs; sum(range(10000)) takes {speed:.2f} ms\n"
    )
    with tempfile.TemporaryDirectory(prefix="fleetcal-bench-") as tmp:
        workdir = Path(tmp)
        if not args.skip_upload:
            print("## Upload over loopback\n")
            print(table(bench_upload(args.upload_mb, workdir, args.repeat)) + "\n", flush=True)

        print(f"## Queries with {args.runs:,} runs over {args.robots} robots\n", flush=True)
        rows = []
        sqlite_url = f"sqlite:///{workdir / 'queries' / 'fleetcal.db'}"
        started = time.perf_counter()
        robots = seed(sqlite_url, runs=args.runs, robots=args.robots)
        print(f"seeded SQLite in {time.perf_counter() - started:.0f} s", flush=True)
        rows += bench_queries(
            "SQLite", {"FLEETCAL_DATA_DIR": str(workdir / "queries")}, robots, args.requests
        )
        if not args.skip_postgres:
            with postgres_database() as pg_url:
                started = time.perf_counter()
                robots = seed(pg_url, runs=args.runs, robots=args.robots)
                print(f"seeded PostgreSQL in {time.perf_counter() - started:.0f} s", flush=True)
                rows += bench_queries(
                    "PostgreSQL",
                    {"FLEETCAL_DATA_DIR": str(workdir / "pg"), "FLEETCAL_DATABASE_URL": pg_url},
                    robots,
                    args.requests,
                )
        print()
        print(table(rows))


if __name__ == "__main__":
    main()
