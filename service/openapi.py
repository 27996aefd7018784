"""The OpenAPI document, generated from the app (never hand-written) and kept in
`openapi/openapi.json`; `tests/service/test_openapi.py` fails when the two differ."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

OPENAPI_PATH = Path(__file__).resolve().parent.parent / "openapi" / "openapi.json"


def openapi_document() -> dict[str, Any]:
    from service.app import create_app
    from service.settings import Settings

    # Building the app touches no database or storage; only the lifespan does.
    return create_app(Settings()).openapi()


def render_openapi() -> str:
    return json.dumps(openapi_document(), indent=2, ensure_ascii=False) + "\n"
