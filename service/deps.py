"""FastAPI dependencies that keep routes short: the app's services, database sessions, and the
caller's API key with the scope checks (`ReadKey`, `AdminKey`, ...)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Path, Request, Security
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from service.auth import Principal, authenticate
from service.db import Database
from service.metrics import Metrics
from service.models import Scope
from service.problem_details import Forbidden, NotReady, Unauthenticated
from service.schemas import ROBOT_ID_PATTERN
from service.settings import Settings
from service.storage import Storage


@dataclass(frozen=True)
class Services:
    """What the lifespan builds and every request shares."""

    settings: Settings
    db: Database
    storage: Storage
    metrics: Metrics


async def get_services(request: Request) -> Services:
    # async: no I/O here, and a sync dependency would cost a thread hop on every request.
    services: Services | None = getattr(request.app.state, "services", None)
    if services is None:
        raise NotReady("the service is starting or stopping; retry shortly")
    return services


ServicesDep = Annotated[Services, Depends(get_services)]


def get_session(services: ServicesDep) -> Iterator[Session]:
    with services.db.session() as session:
        yield session


def get_write_session(services: ServicesDep) -> Iterator[Session]:
    """A session whose transaction the route commits (BEGIN IMMEDIATE on SQLite)."""
    with services.db.write_session() as session:
        yield session


SessionDep = Annotated[Session, Depends(get_session)]
WriteSessionDep = Annotated[Session, Depends(get_write_session)]

_api_key_header = APIKeyHeader(
    name="X-API-Key", auto_error=False, description="An API key made by `fleetcal keys create`."
)
_bearer = HTTPBearer(auto_error=False, description="The same API key as a bearer token.")
_CHALLENGE = {"WWW-Authenticate": 'Bearer realm="fleetcal"'}


def current_key(
    services: ServicesDep,
    api_key: Annotated[str | None, Security(_api_key_header)],
    bearer: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)],
) -> Principal:
    key = api_key or (bearer.credentials if bearer is not None else None)
    if not key:
        raise Unauthenticated(
            "send an API key in the X-API-Key header or as 'Authorization: Bearer <key>'",
            headers=_CHALLENGE,
        )
    with services.db.session() as session:
        principal = authenticate(session, key)
    if principal is None:
        raise Unauthenticated("the API key is unknown or revoked", headers=_CHALLENGE)
    return principal


CurrentKey = Annotated[Principal, Depends(current_key)]


def _require(scope: Scope) -> object:
    async def check(principal: CurrentKey) -> Principal:  # async: no I/O, no thread hop
        if not principal.has(scope):
            raise Forbidden(f"this endpoint needs a key with the '{scope.value}' scope")
        return principal

    return Depends(check)


ReadKey = Annotated[Principal, _require(Scope.READ)]
AdminKey = Annotated[Principal, _require(Scope.ADMIN)]
OverrideKey = Annotated[Principal, _require(Scope.OVERRIDE)]


RobotIdPath = Annotated[str, Path(pattern=ROBOT_ID_PATTERN, description="The robot's id.")]
