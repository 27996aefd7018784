"""`create_app(settings)`: nothing happens until the lifespan starts, which creates the data
directory, applies migrations, and opens storage."""

from __future__ import annotations

from pathlib import Path

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
