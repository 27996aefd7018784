"""`openapi/openapi.json` is the app's document: regenerate it with
`fleetcal openapi --output openapi/openapi.json` when the API changes."""

from __future__ import annotations

import json

from service.openapi import OPENAPI_PATH, openapi_document, render_openapi


def test_the_committed_document_matches_the_app() -> None:
    committed = OPENAPI_PATH.read_text()
    assert json.loads(committed) == openapi_document(), (
        "openapi/openapi.json is out of date: run `fleetcal openapi --output openapi/openapi.json`"
    )
    assert committed == render_openapi()


def test_every_operation_documents_problem_responses() -> None:
    document = openapi_document()
    for path, operations in document["paths"].items():
        for method, operation in operations.items():
            for status in ("4XX", "5XX"):
                content = operation["responses"][status]["content"]
                assert content == {
                    "application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}
                }, (method, path)
    assert set(document["components"]["securitySchemes"]) == {"APIKeyHeader", "HTTPBearer"}
