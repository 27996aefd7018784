"""`create_app(settings)`: the FastAPI application. Nothing happens at import; the lifespan opens
the database (applying migrations), the storage, and sweeps uploads a killed process left behind."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from datetime import timedelta

from anyio import to_thread
from fastapi import FastAPI

from pipeline import __version__
from service.dashboard import router as dashboard_router
from service.db import Database
from service.deps import Services
from service.metrics import Metrics, MetricsMiddleware
from service.problems import install_problem_handlers
from service.routes import exports, fleet, health, reports, robots, runs, tolerance
from service.settings import Settings
from service.storage import make_storage

log = logging.getLogger(__name__)

DESCRIPTION = """\
Upload LiDAR calibration recordings, follow their runs, and query each robot's calibration and
its history. Authenticate with an API key (`X-API-Key: <key>` or `Authorization: Bearer <key>`);
keys have scopes `upload` (optionally bound to one robot), `read` and `admin`.
Every error is an RFC 9457 problem document (`application/problem+json`).
"""


def create_app(settings: Settings) -> FastAPI:
    metrics = Metrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        services = await to_thread.run_sync(start_services, settings, metrics)
        app.state.services = services
        try:
            yield
        finally:
            app.state.services = None
            services.db.dispose()

    app = FastAPI(title="fleetcal", version=__version__, description=DESCRIPTION, lifespan=lifespan)
    app.state.services = None
    install_problem_handlers(app)
    app.add_middleware(MetricsMiddleware, metrics=metrics)
    # Each router carries its full prefix (/v1/...), so route templates in metrics are complete.
    for module in (health, runs, robots, tolerance, fleet, reports, exports):
        app.include_router(module.router)
    app.include_router(dashboard_router)
    return app


def start_services(settings: Settings, metrics: Metrics | None = None) -> Services:
    """Open the database (migrated if `migrate_on_start`) and the storage."""
    db = Database.from_settings(settings)
    if settings.migrate_on_start:
        db.upgrade()
    storage = make_storage(settings)
    swept = storage.sweep_stale_uploads(timedelta(seconds=settings.stale_upload_seconds))
    if swept:
        log.warning("removed %d unfinished uploads left by a stopped process", swept)
    metrics = metrics or Metrics()
    metrics.watch_queue(db)
    return Services(settings=settings, db=db, storage=storage, metrics=metrics)
