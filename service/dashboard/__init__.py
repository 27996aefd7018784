"""The dashboard at `/`: one HTML page and its script and style, no build step. The page asks for
an API key once, keeps it in the browser's session storage and calls the `/v1` API with it; the
server holds no dashboard state and sets no cookie.
"""

from __future__ import annotations

from functools import cache
from importlib import resources

from fastapi import APIRouter
from fastapi.responses import Response

from service.problem_details import NotFound

router = APIRouter(include_in_schema=False)

_ASSETS = {
    "format.js": "text/javascript; charset=utf-8",
    "ticks.js": "text/javascript; charset=utf-8",
    "drift.js": "text/javascript; charset=utf-8",
    "api.js": "text/javascript; charset=utf-8",
    "ui.js": "text/javascript; charset=utf-8",
    "overrides.js": "text/javascript; charset=utf-8",
    "compare.js": "text/javascript; charset=utf-8",
    "webhooks.js": "text/javascript; charset=utf-8",
    "dashboard.js": "text/javascript; charset=utf-8",
    "dashboard.css": "text/css; charset=utf-8",
    "favicon.svg": "image/svg+xml",
}
# Everything comes from this origin; images are blob: URLs the script makes from API responses.
_SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob: data:; "
    "object-src 'none'; base-uri 'none'; frame-ancestors 'none'; form-action 'self'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


@cache
def _asset(name: str) -> bytes:
    return resources.files(__package__).joinpath(name).read_bytes()


@router.get("/")
def index() -> Response:
    return Response(
        _asset("index.html"),
        media_type="text/html; charset=utf-8",
        headers={**_SECURITY_HEADERS, "Cache-Control": "no-cache"},
    )


@router.get("/favicon.ico")
def favicon() -> Response:
    # Browsers ask for /favicon.ico on pages that name no icon (/docs, a bare API URL): the same
    # SVG, which they accept whatever the name says.
    return asset("favicon.svg")


@router.get("/dashboard/{name}")
def asset(name: str) -> Response:
    if name not in _ASSETS:
        raise NotFound(f"no dashboard file {name!r}")
    return Response(
        _asset(name),
        media_type=_ASSETS[name],
        headers={**_SECURITY_HEADERS, "Cache-Control": "no-cache"},
    )
