"""Start-up checks: invalid settings, an unreachable database, an unwritable storage are each one
`StartupError` line that says what to do."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.settings import Settings
from service.startup import (
    StartupError,
    load_settings,
    open_database,
    open_storage,
    where_state_lives,
)
from tests.ports import unused_port


def test_invalid_settings_are_one_line_naming_the_variable_without_its_password(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("FLEETCAL_DATABASE_URL", "mysql://fleet:s3cret@db/fleet")
    monkeypatch.setenv("FLEETCAL_MAX_UPLOAD_BYTES", "lots")
    with pytest.raises(
        StartupError, match=r"^FLEETCAL_DATABASE_URL: 'mysql://fleet:\*\*\*@db"
    ) as e:
        load_settings()
    message = str(e.value)
    assert "\n" not in message and "s3cret" not in message
    assert "FLEETCAL_MAX_UPLOAD_BYTES: " in message


def test_the_data_dir_argument_wins_over_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("FLEETCAL_DATA_DIR", str(tmp_path / "env"))
    assert load_settings().data_dir == tmp_path / "env"
    assert load_settings(tmp_path / "cli").data_dir == tmp_path / "cli"
    assert where_state_lives(load_settings()) == f"data directory {tmp_path / 'env'}"


def test_an_unreachable_database_is_one_line_with_what_to_check() -> None:
    url = f"postgresql+psycopg://fleet:s3cret@127.0.0.1:{unused_port()}/fleet"
    with pytest.raises(
        StartupError, match=r"cannot open the database postgresql\+psycopg://fleet:\*\*\*@"
    ) as e:
        open_database(Settings(database_url=url), migrate=True)
    assert "check FLEETCAL_DATABASE_URL and that the database server is running" in str(e.value)
    assert "\n" not in str(e.value) and "s3cret" not in str(e.value)


def test_a_data_dir_that_is_a_file_is_named_with_the_flag_to_fix(tmp_path: Path) -> None:
    (tmp_path / "state").write_text("not a directory")
    with pytest.raises(StartupError, match=r"cannot open the database sqlite:///.*--data-dir"):
        open_database(Settings(data_dir=tmp_path / "state"), migrate=True)


def test_a_database_behind_its_migrations_is_refused_when_not_migrating(tmp_path: Path) -> None:
    with pytest.raises(StartupError, match="is not current; run `fleetcal db upgrade`"):
        open_database(Settings(data_dir=tmp_path), migrate=False)
    open_database(Settings(data_dir=tmp_path), migrate=True).dispose()
    open_database(Settings(data_dir=tmp_path), migrate=False).dispose()


def test_an_unwritable_storage_is_one_line_naming_it(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("not a directory")
    settings = Settings(storage_url=(tmp_path / "file" / "storage").as_uri())
    with pytest.raises(
        StartupError, match=r"cannot write to the storage file:///.*FLEETCAL_STORAGE_URL"
    ):
        open_storage(settings)
