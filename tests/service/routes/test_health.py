"""Probes and metrics: /healthz, /readyz (database, migrations, storage), /metrics."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings
from tests.service.conftest import Api, problem_type


def test_healthz_and_readyz(api: Api) -> None:
    assert api.client.get("/healthz").json() == {"status": "ok"}
    ready = api.client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json() == {
        "status": "ok",
        "checks": {"database": "ok", "migrations": "ok", "storage": "ok"},
    }


def test_readyz_reports_pending_migrations(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path, migrate_on_start=False)
    with TestClient(create_app(settings)) as client:
        response = client.get("/readyz")
        assert response.status_code == 503 and problem_type(response) == "not-ready"
        checks = response.json()["checks"]
        assert checks["database"] == "ok" and checks["storage"] == "ok"
        assert "fleetcal db upgrade" in checks["migrations"]


def test_readyz_reports_unwritable_storage(api: Api) -> None:
    # A file where the upload directory should be: unwritable even for root.
    tmp = api.storage.root / ".tmp"
    tmp.rmdir()
    tmp.write_bytes(b"")
    response = api.client.get("/readyz")
    assert response.status_code == 503 and problem_type(response) == "not-ready"
    assert response.json()["checks"]["storage"].startswith("not writable")
    assert response.json()["checks"]["database"] == "ok"


def test_metrics_count_requests_uploads_and_queue(api: Api) -> None:
    api.upload("R1")
    api.upload("R1", b"not a recording at all")
    api.client.get("/v1/runs", headers=api.headers("read"))
    text = api.client.get("/metrics").text
    assert (
        'fleetcal_http_requests_total{method="POST",route="/v1/robots/{robot_id}/runs",'
        'status="202"} 1.0'
    ) in text
    assert (
        'fleetcal_http_requests_total{method="POST",route="/v1/robots/{robot_id}/runs",'
        'status="415"} 1.0'
    ) in text
    assert 'fleetcal_uploads_total{outcome="accepted"} 1.0' in text
    assert 'fleetcal_uploads_total{outcome="unsupported-recording-format"} 1.0' in text
    assert "fleetcal_upload_bytes_total 4096.0" in text
    assert 'fleetcal_runs{status="queued"} 1.0' in text
    assert 'fleetcal_runs{status="running"} 0.0' in text
    assert "fleetcal_queue_oldest_age_seconds" in text


def test_unknown_paths_and_methods_are_problems(api: Api) -> None:
    response = api.client.get("/v2/runs")
    assert response.status_code == 404 and problem_type(response) == "not-found"
    response = api.client.delete("/v1/runs", headers=api.headers("admin"))
    assert response.status_code == 405 and problem_type(response) == "method-not-allowed"
