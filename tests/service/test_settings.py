"""Settings: `FLEETCAL_*` environment variables, defaults under the data directory."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from service.settings import Settings


def test_defaults_live_under_the_data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    settings = Settings()
    assert settings.data_dir == Path(".fleetcal")
    assert settings.resolved_database_url == f"sqlite:///{tmp_path / '.fleetcal' / 'fleetcal.db'}"
    assert settings.resolved_storage_url == (tmp_path / ".fleetcal" / "storage").as_uri()


def test_environment_variables_configure_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLEETCAL_DATABASE_URL", "postgresql+psycopg://u@db/fleet")
    monkeypatch.setenv("FLEETCAL_STORAGE_URL", "s3://bucket/prefix")
    monkeypatch.setenv("FLEETCAL_MAX_UPLOAD_BYTES", "1000")
    monkeypatch.setenv("FLEETCAL_RUN_MAX_ATTEMPTS", "5")
    monkeypatch.setenv("FLEETCAL_S3_ENDPOINT_URL", "")
    settings = Settings()
    assert settings.resolved_database_url == "postgresql+psycopg://u@db/fleet"
    assert settings.resolved_storage_url == "s3://bucket/prefix"
    assert settings.max_upload_bytes == 1000 and settings.run_max_attempts == 5
    assert settings.s3_endpoint_url is None  # empty means unset
    # An explicit argument (a CLI's --data-dir) wins over the environment.
    monkeypatch.setenv("FLEETCAL_DATA_DIR", "/from/env")
    assert Settings(data_dir=Path("/from/cli")).data_dir == Path("/from/cli")


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("FLEETCAL_MAX_UPLOAD_BYTES", "0"),
        ("FLEETCAL_MAX_UPLOAD_BYTES", "lots"),
        ("FLEETCAL_S3_PART_SIZE_BYTES", "1024"),
        ("FLEETCAL_MIGRATE_ON_START", "perhaps"),
    ],
)
def test_bad_values_are_refused(monkeypatch: pytest.MonkeyPatch, name: str, value: str) -> None:
    monkeypatch.setenv(name, value)
    with pytest.raises(ValidationError):
        Settings()


@pytest.mark.parametrize(
    ("name", "url", "message"),
    [
        ("STORAGE", "ftp://host/dir", "unsupported storage URL 'ftp://host/dir'"),
        ("STORAGE", "s3:///prefix", "unsupported storage URL 's3:///prefix'"),
        ("STORAGE", "file:relative/dir", "use file:///absolute/dir or s3://bucket"),
        ("STORAGE", "/srv/fleetcal", "unsupported storage URL"),
        ("DATABASE", "localhost:5432/fleet", "is not a database URL; use sqlite:////"),
        (
            "DATABASE",
            "mysql+pymysql://u@db/x",
            "names the database 'mysql'; fleetcal runs on SQLite",
        ),
        ("DATABASE", "postgres://u@db/fleet", "names the database 'postgres'"),
        (
            "DATABASE",
            "postgresql+nodriver://u@db/x",
            "the driver 'nodriver', which is not installed",
        ),
    ],
)
def test_an_unusable_url_is_refused_with_the_forms_to_use(
    monkeypatch: pytest.MonkeyPatch, name: str, url: str, message: str
) -> None:
    monkeypatch.setenv(f"FLEETCAL_{name}_URL", url)
    with pytest.raises(ValidationError, match=message):
        Settings()
