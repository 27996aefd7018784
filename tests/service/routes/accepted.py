"""Runs with results for the override, comparison and CSV tests: stored as a worker stores them."""

from __future__ import annotations

import uuid
from typing import Any

from service import repository
from tests.service.conftest import Api
from tests.service.documents import result_document


def determined(
    *, passed: bool = True, rear_x: float = -0.41, final: float = 0.0012
) -> dict[str, Any]:
    """A result whose LiDARs were all determined (an operator may accept it)."""
    document = result_document(passed=passed, rear_x=rear_x, final=final)
    del document["lidars"]["lidar_left"]
    document["verdict"]["checks"] = [
        c for c in document["verdict"]["checks"] if "left" not in c["name"]
    ]
    return document


def finished(api: Api, document: dict[str, Any], robot: str = "R1") -> str:
    """Upload a run for `robot` and store `document` as its result; the run's id."""
    response = api.upload(robot)
    assert response.status_code == 202, response.text
    run_id = response.json()["id"]
    with api.services.db.transaction() as session:
        repository.store_result(session, uuid.UUID(run_id), document)
    return str(run_id)
