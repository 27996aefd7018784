"""`create_app(settings)`: nothing happens until the lifespan starts, which creates the data
directory, applies migrations, and opens storage."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings


def test_nothing_is_created_before_start_then_everything_on_first_start(tmp_path: Path) -> None:
    data_dir = tmp_path / "fresh"
    app = create_app(Settings(data_dir=data_dir))
    assert not data_dir.exists()
    with TestClient(app) as client:
        assert (data_dir / "fleetcal.db").is_file()
        assert (data_dir / "storage" / ".tmp").is_dir()
        assert client.get("/readyz").json()["checks"]["migrations"] == "ok"
    assert app.state.services is None
    # A second start on the same directory finds it migrated.
    with TestClient(create_app(Settings(data_dir=data_dir))) as client:
        assert client.get("/readyz").status_code == 200


def test_requests_before_start_are_problems_not_crashes(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path))
    client = TestClient(app)  # no `with`: the lifespan never ran
    response = client.get("/v1/runs", headers={"X-API-Key": "x"})
    assert response.status_code == 503
    assert response.json()["type"] == "urn:fleetcal:problem:not-ready"
    assert not (tmp_path / "fleetcal.db").exists()


@pytest.mark.parametrize(
    ("method", "path", "allowed"),
    [
        # Starlette named the first route's methods only: `GET` where PUT is served too.
        ("DELETE", "/v1/robots/R1", "GET, PUT"),
        ("POST", "/v1/robots/R1", "GET, PUT"),
        ("DELETE", "/v1/tolerance-profiles/p1", "GET, PUT"),
        ("GET", "/v1/robots/R1/runs", "POST"),
        ("POST", "/v1/runs", "GET"),
        ("PUT", "/healthz", "GET"),
    ],
)
def test_a_405_lists_every_method_of_its_path(
    tmp_path: Path, method: str, path: str, allowed: str
) -> None:
    client = TestClient(create_app(Settings(data_dir=tmp_path)))  # routing needs no lifespan
    response = client.request(method, path)
    assert response.status_code == 405
    assert response.headers["allow"] == allowed
    assert response.json()["type"] == "urn:fleetcal:problem:method-not-allowed"
    assert response.json()["detail"] == f"{method} is not served here; this path allows {allowed}"
