"""`create_app(settings)`: the FastAPI application. Nothing happens at import; the lifespan opens
the database (applying migrations), the storage, and sweeps the uploads and recordings a killed
process left behind."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from datetime import timedelta
from http import HTTPStatus

from anyio import to_thread
from fastapi import Depends, FastAPI, Request
from fastapi.responses import JSONResponse
from starlette.routing import Match

from pipeline import __version__
from service import repository
from service.api_docs import install_api_docs
from service.dashboard import router as dashboard_router
from service.db import Database
from service.deps import Services
from service.metrics import Metrics, MetricsMiddleware
from service.parameters import refuse_repeated_query_parameters
from service.problem_details import MethodNotAllowed, install_problem_handlers, problem_response
from service.routes import (
    comparison,
    csv_exports,
    exports,
    fleet,
    health,
    keys,
    overrides,
    reports,
    robots,
    runs,
    tolerance,
    webhooks,
)
from service.settings import Settings
from service.storage import Storage, make_storage

log = logging.getLogger(__name__)

DESCRIPTION = """\
Upload LiDAR calibration recordings, follow their runs, and query each robot's calibration and
its history. Authenticate with an API key (`X-API-Key: <key>` or `Authorization: Bearer <key>`);
keys have scopes `upload` (optionally bound to one robot), `read`, `override` (accept or reject a
verdict) and `admin` (everything).
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

    app = FastAPI(
        title="fleetcal",
        version=__version__,
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # install_api_docs: the same pages, their assets served from here
        redoc_url=None,
        dependencies=[Depends(refuse_repeated_query_parameters)],
    )
    install_api_docs(app)
    app.state.services = None
    install_problem_handlers(app)
    app.add_exception_handler(HTTPStatus.METHOD_NOT_ALLOWED, method_not_allowed)
    app.add_middleware(MetricsMiddleware, metrics=metrics)
    # Each router carries its full prefix (/v1/...), so route templates in metrics are complete.
    for module in (
        health,
        runs,
        overrides,
        robots,
        comparison,
        tolerance,
        fleet,
        reports,
        exports,
        csv_exports,
        webhooks,
        keys,
    ):
        app.include_router(module.router)
    app.include_router(dashboard_router)
    return app


_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(request: Request) -> list[str]:
    """The methods some route of the app serves at the request's path."""
    routes = request.app.router.routes
    return [
        method
        for method in _METHODS
        if any(
            route.matches({**request.scope, "method": method})[0] is Match.FULL for route in routes
        )
    ]


async def method_not_allowed(request: Request, exc: Exception) -> JSONResponse:
    # Starlette's own 405 names the methods of the first route on the path only: `GET` on
    # /v1/robots/{robot_id}, where PUT is served too.
    allowed = ", ".join(allowed_methods(request))
    return problem_response(
        MethodNotAllowed(
            f"{request.method} is not served here; this path allows {allowed}",
            headers={"Allow": allowed},
        )
    )


def sweep_orphan_recordings(db: Database, storage: Storage, older_than: timedelta) -> int:
    """Delete stored recordings older than `older_than` that no run points at; return how many.

    An upload is moved into place just before its run is committed; a process killed in between
    leaves the file behind. The age keeps this clear of uploads still being recorded.
    """
    keys = list(storage.keys_older_than(repository.RECORDINGS, older_than))
    if not keys:
        return 0
    with db.session() as session:
        orphans = repository.unreferenced_recordings(session, keys)
    for key in orphans:
        storage.delete(key)
    return len(orphans)


def start_services(settings: Settings, metrics: Metrics | None = None) -> Services:
    """Open the database (migrated if `migrate_on_start`) and the storage."""
    db = Database.from_settings(settings)
    if settings.migrate_on_start:
        db.upgrade()
    storage = make_storage(settings)
    stale = timedelta(seconds=settings.stale_upload_seconds)
    swept = storage.sweep_stale_uploads(stale)
    if swept:
        log.warning("removed %d unfinished uploads left by a stopped process", swept)
    orphans = sweep_orphan_recordings(db, storage, stale)
    if orphans:
        log.warning(
            "removed %d stored recordings no run points at (a process stopped between "
            "storing an upload and recording its run)",
            orphans,
        )
    metrics = metrics or Metrics()
    metrics.watch_queue(db)
    return Services(settings=settings, db=db, storage=storage, metrics=metrics)
