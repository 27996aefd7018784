"""`fleetcal serve` and `fleetcal worker` start-up: every misconfiguration is one line with what to
do and exit 2, before a key (or a database) is created; the first start shows its admin key."""

from __future__ import annotations

import socket
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from service.db import Database
from service.models import ApiKey
from service.settings import Settings
from tests.ports import unused_port
from tests.workers.runs import ROOT, entrypoint_env
from workers.cli import app


@pytest.fixture
def busy_port() -> Iterator[int]:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        yield int(taken.getsockname()[1])


def fleetcal(*args: str, **env: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args), env=env)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    return result.exit_code, result.stdout, result.stderr


def key_count(data_dir: Path) -> int:
    db = Database.from_settings(Settings(data_dir=data_dir))
    try:
        with db.session() as session:
            return int(session.scalar(select(func.count()).select_from(ApiKey)) or 0)
    finally:
        db.dispose()


def test_serve_on_a_busy_port_is_one_line_and_creates_nothing(
    tmp_path: Path, busy_port: int
) -> None:
    code, out, err = fleetcal(
        "serve", "--data-dir", str(tmp_path / "state"), "--port", str(busy_port)
    )
    assert code == 2
    assert err == (
        f"error: cannot listen on 127.0.0.1:{busy_port}: Address already in use; another process "
        "listens there: stop it or choose a free port with --port\n"
    )
    assert "admin key" not in out
    assert not (tmp_path / "state").exists(), "the port is checked before the database is made"


@pytest.mark.parametrize(
    ("variable", "value", "message"),
    [
        ("FLEETCAL_DATABASE_URL", "not a url", "error: FLEETCAL_DATABASE_URL: 'not a url' is not"),
        (
            "FLEETCAL_DATABASE_URL",
            "postgresql+psycopg://u@127.0.0.1:{port}/db",
            "error: cannot open the database postgresql+psycopg://u@127.0.0.1",
        ),
        ("FLEETCAL_STORAGE_URL", "ftp://host/dir", "error: FLEETCAL_STORAGE_URL: unsupported"),
    ],
)
@pytest.mark.parametrize("command", ["serve", "worker"])
def test_a_bad_setting_stops_the_start_with_one_line(
    tmp_path: Path, command: str, variable: str, value: str, message: str
) -> None:
    value = value.format(port=unused_port())
    args = [command, "--data-dir", str(tmp_path / "state")]
    code, out, err = (
        fleetcal(*args, "--port", "0", **{variable: value})
        if command == "serve"
        else fleetcal(*args, **{variable: value})
    )
    assert code == 2
    assert err.startswith(message) and err.count("\n") == 1, err
    assert "admin key" not in out


def test_an_unwritable_storage_stops_serve_before_the_admin_key(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("not a directory")
    storage = (tmp_path / "file" / "storage").as_uri()
    state = tmp_path / "state"
    code, out, err = fleetcal(
        "serve", "--data-dir", str(state), "--port", "0", FLEETCAL_STORAGE_URL=storage
    )
    assert code == 2 and err.startswith(f"error: cannot write to the storage {storage}")
    assert "admin key" not in out
    assert key_count(state) == 0


def test_the_first_serve_prints_its_admin_key_with_a_keys_hint_naming_the_data_dir(
    tmp_path: Path,
) -> None:
    state = tmp_path / "state"
    with subprocess.Popen(
        ["fleetcal", "serve", "--data-dir", str(state), "--port", "0", "--workers", "0"],
        env=entrypoint_env(),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    ) as serve:
        assert serve.stdout is not None
        lines = []
        try:
            for line in serve.stdout:
                lines.append(line)
                if line.startswith("Make keys"):
                    break
        finally:
            serve.terminate()
        assert serve.wait(60) == 0
    assert lines[0].startswith("fleetcal API at http://127.0.0.1:")
    assert lines[1] == "Created the first admin key; it is shown only this once, store it now:\n"
    assert lines[2].strip().startswith("fck_")
    assert f"`fleetcal keys create --scope read --data-dir {state}`" in lines[3]
    assert key_count(state) == 1
