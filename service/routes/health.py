"""Liveness, readiness and Prometheus metrics (no key needed: probes and scrapers have none)."""

from __future__ import annotations

from anyio import to_thread
from fastapi import APIRouter
from fastapi.responses import Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from sqlalchemy import text

from service.deps import Services, ServicesDep
from service.problem_details import PROBLEM_RESPONSES, NotReady
from service.schemas import Health, Readiness
from service.storage import StorageError

router = APIRouter(tags=["health"], responses=PROBLEM_RESPONSES)


@router.get("/healthz", summary="The process is alive")
def healthz() -> Health:
    return Health()


@router.get("/readyz", summary="Database reachable, migrations current, storage writable")
async def readyz(services: ServicesDep) -> Readiness:
    checks = await to_thread.run_sync(_checks, services)
    if any(value != "ok" for value in checks.values()):
        failing = ", ".join(f"{name}: {value}" for name, value in checks.items() if value != "ok")
        raise NotReady(f"not ready: {failing}", checks=checks)
    return Readiness(status="ok", checks=checks)


@router.get(
    "/metrics",
    summary="Prometheus metrics",
    response_class=Response,
    responses={
        200: {
            "content": {CONTENT_TYPE_LATEST: {}},
            "description": "Prometheus text exposition format.",
        }
    },
)
async def metrics(services: ServicesDep) -> Response:
    body = await to_thread.run_sync(generate_latest, services.metrics.registry)
    return Response(body, media_type=CONTENT_TYPE_LATEST)


def _checks(services: Services) -> dict[str, str]:
    checks: dict[str, str] = {}
    try:
        with services.db.engine.connect() as connection:
            connection.execute(text("SELECT 1"))
        checks["database"] = "ok"
        current, head = services.db.current_revisions(), services.db.head_revisions()
        checks["migrations"] = (
            "ok"
            if current == head
            else (
                f"at {sorted(current) or 'nothing'}, expected {sorted(head)}: "
                "run `fleetcal db upgrade`"
            )
        )
    except Exception as err:  # any driver error means "not ready", with its message
        checks["database"] = f"unreachable: {type(err).__name__}"
        checks.setdefault("migrations", "unknown")
    try:
        services.storage.check_writable()
        checks["storage"] = "ok"
    except StorageError as err:
        checks["storage"] = f"not writable: {err}"
    return checks
