"""Prometheus metrics: request counts and latencies by route, upload volume and outcomes, and the
queue's state (runs per status, age of the oldest queued run) read from the database at scrape.

Each app has its own registry, so apps built side by side (tests) never share counters.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from datetime import UTC, datetime

from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service import repository
from service.db import Database


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.requests = Counter(
            "fleetcal_http_requests",
            "HTTP requests answered.",
            ["method", "route", "status"],
            registry=self.registry,
        )
        self.latency = Histogram(
            "fleetcal_http_request_duration_seconds",
            "Time to answer an HTTP request.",
            ["method", "route"],
            registry=self.registry,
            buckets=(0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60),
        )
        self.upload_bytes = Counter(
            "fleetcal_upload_bytes", "Recording bytes accepted.", registry=self.registry
        )
        self.uploads = Counter(
            "fleetcal_uploads",
            "Upload attempts by outcome (accepted, replayed, or problem type).",
            ["outcome"],
            registry=self.registry,
        )
        self._queue: _QueueCollector | None = None

    def watch_queue(self, database: Database) -> None:
        """Report the queue of `database` (replacing the one watched before, if any)."""
        if self._queue is not None:
            self.registry.unregister(self._queue)
        self._queue = _QueueCollector(database)
        self.registry.register(self._queue)


class _QueueCollector(Collector):
    def __init__(self, database: Database) -> None:
        self._database = database

    def collect(self) -> Iterator[GaugeMetricFamily]:
        runs = GaugeMetricFamily("fleetcal_runs", "Runs per status.", labels=["status"])
        oldest = GaugeMetricFamily(
            "fleetcal_queue_oldest_age_seconds", "Age of the oldest claimable queued run."
        )
        with self._database.session() as session:
            for status, count in repository.count_runs_by_status(session).items():
                runs.add_metric([status.value], count)
            oldest_at = repository.oldest_queued_at(session)
        age = 0.0 if oldest_at is None else (datetime.now(UTC) - oldest_at).total_seconds()
        oldest.add_metric([], max(age, 0.0))
        yield runs
        yield oldest

    def describe(self) -> Iterator[GaugeMetricFamily]:
        # Describing without collecting keeps registration from querying the database.
        yield GaugeMetricFamily("fleetcal_runs", "Runs per status.", labels=["status"])
        yield GaugeMetricFamily("fleetcal_queue_oldest_age_seconds", "")


class MetricsMiddleware:
    """Counts and times every HTTP request under its route template (not its raw path)."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            route = scope.get("route")
            template = getattr(route, "path", None) or "unmatched"
            method = scope.get("method", "")
            self.metrics.requests.labels(method, template, str(status)).inc()
            self.metrics.latency.labels(method, template).observe(time.perf_counter() - started)
