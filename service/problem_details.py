"""RFC 9457 problem details: the API's error types and the one mapping from exceptions to
`application/problem+json` responses. The worker stores the same documents in `runs.error`."""

from __future__ import annotations

import errno
import logging
from http import HTTPStatus
from typing import Any, ClassVar

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy.exc import OperationalError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.requests import ClientDisconnect

from service.storage import StorageError, StorageFullError

PROBLEM_MEDIA_TYPE = "application/problem+json"
PROBLEM_TYPE_PREFIX = "urn:fleetcal:problem:"
"""Problem types are URNs (RFC 9457 allows non-resolvable URIs): stable names, no hosting needed."""

log = logging.getLogger(__name__)


class Problem(BaseModel):
    """An RFC 9457 problem document. Extension members (e.g. `errors`) may follow."""

    model_config = ConfigDict(extra="allow")

    type: str = Field(examples=[f"{PROBLEM_TYPE_PREFIX}upload-too-large"])
    title: str
    status: int
    detail: str


def problem_document(
    slug: str, title: str, status: int, detail: str, **extra: Any
) -> dict[str, Any]:
    """A problem document as a plain dict (what `runs.error` stores)."""
    return {
        "type": PROBLEM_TYPE_PREFIX + slug,
        "title": title,
        "status": status,
        "detail": detail,
        **extra,
    }


class ApiError(Exception):
    """An error the API answers with a problem document; subclasses fix its type and status."""

    slug: ClassVar[str] = "error"
    title: ClassVar[str] = "Error"
    status: ClassVar[int] = HTTPStatus.BAD_REQUEST

    def __init__(self, detail: str, *, headers: dict[str, str] | None = None, **extra: Any) -> None:
        super().__init__(detail)
        self.detail = detail
        self.headers = headers or {}
        self.extra = extra

    def document(self) -> dict[str, Any]:
        return problem_document(self.slug, self.title, self.status, self.detail, **self.extra)


def _error(slug: str, title: str, status: HTTPStatus) -> type[ApiError]:
    name = "".join(part.capitalize() for part in slug.split("-")) + "Error"
    return type(name, (ApiError,), {"slug": slug, "title": title, "status": status})


# Authentication and authorisation.
Unauthenticated = _error("unauthenticated", "Missing or invalid API key", HTTPStatus.UNAUTHORIZED)
Forbidden = _error("forbidden", "The API key does not allow this", HTTPStatus.FORBIDDEN)
# Lookups.
RobotNotFound = _error("robot-not-found", "No such robot", HTTPStatus.NOT_FOUND)
RunNotFound = _error("run-not-found", "No such run", HTTPStatus.NOT_FOUND)
NoCalibration = _error("no-calibration", "No accepted calibration yet", HTTPStatus.NOT_FOUND)
ProfileNotFound = _error(
    "tolerance-profile-not-found", "No such tolerance profile", HTTPStatus.NOT_FOUND
)
NotFound = _error("not-found", "Not found", HTTPStatus.NOT_FOUND)
WebhookNotFound = _error("webhook-not-found", "No such webhook", HTTPStatus.NOT_FOUND)
# Request shape.
InvalidRequest = _error("invalid-request", "Invalid request", HTTPStatus.UNPROCESSABLE_ENTITY)
InvalidCursor = _error("invalid-cursor", "Invalid pagination cursor", HTTPStatus.BAD_REQUEST)
InvalidHeader = _error("invalid-header", "Invalid request header", HTTPStatus.BAD_REQUEST)
InvalidConfig = _error(
    "invalid-config", "Invalid calibration config", HTTPStatus.UNPROCESSABLE_ENTITY
)
MethodNotAllowed = _error("method-not-allowed", "Method not allowed", HTTPStatus.METHOD_NOT_ALLOWED)
Conflict = _error("conflict", "Conflicting request", HTTPStatus.CONFLICT)
OverrideConflict = _error(
    "override-conflict", "The override does not apply to this result", HTTPStatus.CONFLICT
)
# Uploads.
EmptyUpload = _error("empty-upload", "Empty upload", HTTPStatus.BAD_REQUEST)
ContentLengthMismatch = _error(
    "content-length-mismatch", "Body length differs from Content-Length", HTTPStatus.BAD_REQUEST
)
UploadTooLarge = _error("upload-too-large", "Upload too large", HTTPStatus.REQUEST_ENTITY_TOO_LARGE)
UnsupportedRecording = _error(
    "unsupported-recording-format", "Not a recording", HTTPStatus.UNSUPPORTED_MEDIA_TYPE
)
ChecksumMismatch = _error("checksum-mismatch", "SHA-256 mismatch", HTTPStatus.UNPROCESSABLE_ENTITY)
IdempotencyKeyReused = _error(
    "idempotency-key-reused",
    "Idempotency key already used for another upload",
    HTTPStatus.UNPROCESSABLE_ENTITY,
)
ClientDisconnected = _error(
    "client-disconnected", "Client disconnected during the upload", HTTPStatus.BAD_REQUEST
)
# The service's own state.
InsufficientStorage = _error(
    "insufficient-storage", "Storage full", HTTPStatus.INSUFFICIENT_STORAGE
)
StorageUnavailable = _error(
    "storage-unavailable", "Storage unavailable", HTTPStatus.SERVICE_UNAVAILABLE
)
DatabaseUnavailable = _error(
    "database-unavailable", "Database unavailable", HTTPStatus.SERVICE_UNAVAILABLE
)
NotReady = _error("not-ready", "Service not ready", HTTPStatus.SERVICE_UNAVAILABLE)


def problem_for(exc: Exception) -> ApiError:
    """The one mapping from any exception to the problem the client sees."""
    if isinstance(exc, ApiError):
        return exc
    if isinstance(exc, RequestValidationError):
        errors = [
            {
                "loc": list(err.get("loc", ())),
                "msg": str(err.get("msg", "")),
                "type": str(err.get("type", "")),
            }
            for err in exc.errors()
        ]
        where = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in errors)
        return InvalidRequest(f"the request does not match the API: {where}", errors=errors)
    if isinstance(exc, StarletteHTTPException):
        if exc.status_code == HTTPStatus.NOT_FOUND:
            return NotFound("no such endpoint; see /docs or openapi/openapi.json")
        generic = _error(
            "http-error", HTTPStatus(exc.status_code).phrase, HTTPStatus(exc.status_code)
        )
        return generic(str(exc.detail), headers=dict(exc.headers or {}))
    if isinstance(exc, ClientDisconnect):
        return ClientDisconnected("the client closed the connection before the body was complete")
    if isinstance(exc, StorageFullError) or (
        isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)
    ):
        return InsufficientStorage(f"{exc}; nothing was kept, retry when space is freed")
    if isinstance(exc, StorageError):
        return StorageUnavailable(f"{exc}; nothing was kept, retry later")
    if isinstance(exc, OperationalError):
        return DatabaseUnavailable("the database cannot be reached or is busy; retry later")
    internal = _error("internal-error", "Internal server error", HTTPStatus.INTERNAL_SERVER_ERROR)
    return internal("an unexpected error occurred; it has been logged")


async def _handle(request: Request, exc: Exception) -> JSONResponse:
    problem = problem_for(exc)
    if problem.status >= HTTPStatus.INTERNAL_SERVER_ERROR:
        log.error(
            "%s %s -> %s",
            request.method,
            request.url.path,
            problem.slug,
            exc_info=(type(exc), exc, exc.__traceback__),
        )
    return problem_response(problem)


def problem_response(problem: ApiError) -> JSONResponse:
    return JSONResponse(
        problem.document(),
        status_code=problem.status,
        headers=problem.headers,
        media_type=PROBLEM_MEDIA_TYPE,
    )


def install_problem_handlers(app: FastAPI) -> None:
    handled: tuple[type[Exception], ...] = (
        ApiError,
        RequestValidationError,
        StarletteHTTPException,
        ClientDisconnect,
        StorageError,
        OperationalError,
        Exception,  # anything else: a 500 problem, logged with its traceback
    )
    for exc_type in handled:
        app.add_exception_handler(exc_type, _handle)


_PROBLEM_CONTENT = {
    "description": "A problem document (RFC 9457).",
    "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
}
PROBLEM_RESPONSES: dict[int | str, dict[str, Any]] = {
    "4XX": _PROBLEM_CONTENT,
    "5XX": _PROBLEM_CONTENT,
}
"""Documents the error responses of every route (`Problem` is in the schemas via `RunPublic`)."""
