"""What every command that starts from the service's settings checks first: the settings are
valid, the database answers, the storage takes writes. Each failure is one `StartupError` whose
message says what to do, raised before anything (a key, a run, a file) is created."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ValidationError

if TYPE_CHECKING:
    from service.db import Database
    from service.settings import Settings
    from service.storage import Storage


class StartupError(Exception):
    """A setting is invalid or what it names cannot be reached; the message says what to do."""


def load_settings(data_dir: Path | None = None) -> Settings:
    """`Settings` from the `FLEETCAL_*` environment, with `data_dir` (a `--data-dir`) over it."""
    from service.settings import Settings

    try:
        return Settings(data_dir=data_dir) if data_dir is not None else Settings()
    except ValidationError as err:
        raise StartupError(settings_error_line(err)) from None


def settings_error_line(err: ValidationError) -> str:
    """`FLEETCAL_NAME: reason` for each invalid setting, on one line (the refused value is left
    out: a database URL may hold a password)."""
    reasons = []
    for error in err.errors():
        field = str(error["loc"][0]).upper() if error["loc"] else "SETTINGS"
        reason = error.get("ctx", {}).get("error") or error["msg"]
        reasons.append(f"FLEETCAL_{field}: {reason}")
    return "; ".join(reasons)


def shown_database(settings: Settings) -> str:
    """The database URL with its password hidden."""
    from sqlalchemy import make_url

    return make_url(settings.resolved_database_url).render_as_string(hide_password=True)


def sqlite_file(settings: Settings) -> Path | None:
    """The file of a SQLite database on disk; None for PostgreSQL or an in-memory SQLite."""
    from sqlalchemy import make_url

    url = make_url(settings.resolved_database_url)
    if url.get_backend_name() != "sqlite" or url.database in (None, "", ":memory:"):
        return None
    return Path(url.database)


def where_state_lives(settings: Settings) -> str:
    """`data directory /abs/dir` for the embedded default, else the database it uses."""
    if settings.database_url is None:
        return f"data directory {settings.data_dir.resolve()}"
    return f"database {shown_database(settings)}"


def open_database(settings: Settings, *, migrate: bool | None) -> Database:
    """The settings' database, reached, then migrated (`migrate=True`), checked to be current
    (`False`) or left as it is (`None`, for the `db` commands)."""
    from sqlalchemy.exc import SQLAlchemyError

    from service.db import Database

    db: Database | None = None
    try:
        db = Database.from_settings(settings)
        if migrate is None:
            with db.engine.connect():
                pass
        elif migrate:
            db.upgrade()
        elif not db.migrations_current():
            raise StartupError(
                f"the schema of the database {shown_database(settings)} is not current; run "
                "`fleetcal db upgrade` (or the image's `migrate` entrypoint) first"
            )
    except StartupError:
        if db is not None:
            db.dispose()
        raise
    except (SQLAlchemyError, OSError) as err:
        if db is not None:
            db.dispose()
        raise StartupError(
            f"cannot open the database {shown_database(settings)}: {_cause(err)}; "
            + _database_hint(settings)
        ) from None
    return db


def open_storage(settings: Settings) -> Storage:
    """The settings' storage, with a probe object written and removed."""
    from service.storage import StorageError, make_storage

    try:
        storage = make_storage(settings)
        storage.check_writable()
    except (StorageError, OSError, ValueError) as err:
        raise StartupError(
            f"cannot write to the storage {settings.resolved_storage_url}: {_cause(err)}; check "
            "FLEETCAL_STORAGE_URL (or --data-dir) and the storage's credentials and permissions"
        ) from None
    return storage


def _database_hint(settings: Settings) -> str:
    if sqlite_file(settings) is not None:
        return (
            "check that --data-dir (or FLEETCAL_DATA_DIR, FLEETCAL_DATABASE_URL) names a "
            "writable directory"
        )
    return "check FLEETCAL_DATABASE_URL and that the database server is running and reachable"


def _cause(err: BaseException) -> str:
    """The first line of the driver's own message (SQLAlchemy's adds the statement and a link)."""
    from sqlalchemy.exc import DBAPIError

    if isinstance(err, DBAPIError) and err.orig is not None:
        err = err.orig
    if isinstance(err, OSError) and err.strerror:
        return f"{err.filename}: {err.strerror}" if err.filename else err.strerror
    lines = str(err).strip().splitlines()
    return lines[0].strip() if lines else type(err).__name__
