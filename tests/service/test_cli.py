"""The service's CLI commands through the root `fleetcal` app: keys, db, openapi."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from service.auth import authenticate
from service.db import Database
from service.models import Scope
from service.openapi import OPENAPI_PATH
from service.settings import Settings
from tests.ports import unused_port
from workers.cli import app

runner = CliRunner()


def _fleetcal(*args: str) -> tuple[int, str, str]:
    result = runner.invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def test_keys_create_prints_the_key_once_and_it_works(tmp_path: Path) -> None:
    code, out, err = _fleetcal(
        "keys",
        "create",
        "--scope",
        "upload",
        "--robot",
        "R1",
        "--name",
        "line 3",
        "--data-dir",
        str(tmp_path),
    )
    assert code == 0, err
    secret = out.strip()
    assert secret.startswith("fck_") and "\n" not in secret
    assert "will not be shown again" in err and secret not in err

    db = Database.from_settings(Settings(data_dir=tmp_path))
    with db.session() as session:
        principal = authenticate(session, secret)
    db.dispose()
    assert principal is not None
    assert principal.scopes == {Scope.UPLOAD} and principal.robot_id == "R1"

    code, out, _ = _fleetcal("keys", "list", "--data-dir", str(tmp_path))
    assert code == 0 and principal.key_id in out and "R1" in out and "line 3" in out
    # The secret part may itself hold "_" (URL-safe base64): split at the first two only.
    assert secret not in out and secret.split("_", 2)[2] not in out

    code, out, _ = _fleetcal("keys", "revoke", principal.key_id, "--data-dir", str(tmp_path))
    assert code == 0 and "revoked" in out
    db = Database.from_settings(Settings(data_dir=tmp_path))
    with db.session() as session:
        assert authenticate(session, secret) is None
    db.dispose()
    _, out, _ = _fleetcal("keys", "list", "--data-dir", str(tmp_path))
    assert "revoked" in out


def test_keys_create_refuses_bad_requests(tmp_path: Path) -> None:
    code, _, err = _fleetcal(
        "keys", "create", "--scope", "read", "--robot", "R1", "--data-dir", str(tmp_path)
    )
    assert code == 2 and "only --scope upload" in err
    code, _, err = _fleetcal("keys", "create", "--scope", "root", "--data-dir", str(tmp_path))
    assert code == 2
    code, _, err = _fleetcal(
        "keys", "create", "--scope", "upload", "--robot", "a/b", "--data-dir", str(tmp_path)
    )
    assert code == 2 and "robot id" in err
    assert _fleetcal("db", "upgrade", "--data-dir", str(tmp_path))[0] == 0
    code, _, err = _fleetcal("keys", "revoke", "nope", "--data-dir", str(tmp_path))
    assert code == 1 and "no key" in err


def test_db_upgrade_and_current(tmp_path: Path) -> None:
    code, _, _ = _fleetcal("db", "current", "--data-dir", str(tmp_path))
    assert code == 1
    code, out, err = _fleetcal("db", "upgrade", "--data-dir", str(tmp_path))
    assert code == 0, err
    assert "at revision 0002" in out and (tmp_path / "fleetcal.db").is_file()
    code, out, _ = _fleetcal("db", "current", "--data-dir", str(tmp_path))
    assert code == 0 and "up to date" in out


def test_openapi_prints_writes_and_checks(tmp_path: Path) -> None:
    code, out, _ = _fleetcal("openapi")
    assert code == 0 and out == OPENAPI_PATH.read_text()
    target = tmp_path / "openapi.json"
    assert _fleetcal("openapi", "--output", str(target))[0] == 0
    assert target.read_text() == out
    assert _fleetcal("openapi", "--output", str(target), "--check")[0] == 0
    target.write_text("{}")
    code, _, err = _fleetcal("openapi", "--output", str(target), "--check")
    assert code == 1 and "out of date" in err


def test_keys_say_which_data_directory_they_use_and_take_fleetcal_data_dir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    state = tmp_path / "state"
    monkeypatch.setenv("FLEETCAL_DATA_DIR", str(state))
    code, _, err = _fleetcal("keys", "create", "--scope", "read")
    assert code == 0, err
    assert f"using the data directory {state} (new: created now)" in err
    assert (state / "fleetcal.db").is_file()
    code, listed, err = _fleetcal("keys", "list")
    assert code == 0 and f"using the data directory {state}\n" in err
    assert "read" in listed


@pytest.mark.parametrize("command", [["keys", "list"], ["keys", "revoke", "k1"]])
def test_keys_in_a_directory_no_service_used_are_refused_and_create_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: list[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    code, _, err = _fleetcal(*command)
    assert code == 2
    assert err == (
        f"error: no database in data directory {tmp_path / '.fleetcal'}: no service has used it "
        "yet; pass --data-dir DIR (or set FLEETCAL_DATA_DIR) to the directory `fleetcal serve` "
        "uses\n"
    )
    assert not (tmp_path / ".fleetcal").exists()


@pytest.mark.parametrize(
    ("variable", "value", "message"),
    [
        ("FLEETCAL_DATABASE_URL", "localhost/fleet", "error: FLEETCAL_DATABASE_URL: 'localhost/"),
        ("FLEETCAL_STORAGE_URL", "ftp://x/y", "error: FLEETCAL_STORAGE_URL: unsupported storage"),
    ],
)
def test_commands_with_invalid_settings_exit_2_with_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, variable: str, value: str, message: str
) -> None:
    monkeypatch.setenv(variable, value)
    for command in (["keys", "create", "--scope", "read"], ["db", "upgrade"]):
        result = runner.invoke(app, [*command, "--data-dir", str(tmp_path / "state")])
        assert result.exit_code == 2 and isinstance(result.exception, SystemExit)
        assert result.stderr.startswith(message) and result.stderr.count("\n") == 1
        assert not (tmp_path / "state").exists()


def test_db_commands_on_an_unreachable_database_exit_2_with_one_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    url = f"postgresql+psycopg://u@127.0.0.1:{unused_port()}/db"
    monkeypatch.setenv("FLEETCAL_DATABASE_URL", url)
    for command in (["db", "upgrade"], ["db", "current"], ["keys", "list"]):
        code, _, err = _fleetcal(*command)
        assert code == 2 and err.startswith("error: cannot open the database postgresql")
        assert err.count("\n") == 1


def test_the_dashboard_sign_in_hint_names_the_data_dir() -> None:
    script = (Path(__file__).parents[2] / "service" / "dashboard" / "dashboard.js").read_text()
    assert script.count("fleetcal keys create") == 1
    assert "fleetcal keys create --scope read --data-dir DIR" in script
