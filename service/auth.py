"""API keys: creation (the secret is shown once), hashing, lookup, and the scope rules.

A key reads `fck_<id>_<secret>`. The id is public and finds the row; the sha256 of the whole key is
stored and compared in constant time. `admin` implies every scope. An `upload` key uploads and reads
the runs, calibration and history of its robot (a robot polls its verdict and fetches its
calibration); bound to a robot it may do so for that robot only, unbound (a factory line) for any.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from dataclasses import dataclass
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session

from service.models import ApiKey, Scope

KEY_PREFIX = "fck"
_KEY_PATTERN = re.compile(rf"^{KEY_PREFIX}_([0-9a-f]{{12}})_([A-Za-z0-9_-]{{43}})$")


@dataclass(frozen=True)
class Principal:
    """Who is calling: the key's id, scopes and optional robot binding (never the secret)."""

    key_id: str
    scopes: frozenset[Scope]
    robot_id: str | None

    def has(self, scope: Scope) -> bool:
        return Scope.ADMIN in self.scopes or scope in self.scopes

    def may_upload_for(self, robot_id: str) -> bool:
        if Scope.ADMIN in self.scopes:
            return True
        return Scope.UPLOAD in self.scopes and self.robot_id in (None, robot_id)

    def may_read_robot(self, robot_id: str) -> bool:
        return self.has(Scope.READ) or (
            Scope.UPLOAD in self.scopes and self.robot_id in (None, robot_id)
        )


@dataclass(frozen=True)
class NewKey:
    """A freshly created key: `secret` is the only copy of the full key, print it once."""

    id: str
    secret: str
    scopes: tuple[Scope, ...]
    robot_id: str | None


def hash_key(key: str) -> str:
    return hashlib.sha256(key.encode()).hexdigest()


def create_key(
    session: Session, scopes: list[Scope], *, robot_id: str | None = None, name: str | None = None
) -> NewKey:
    """Store a new key (hashed) in `session`'s transaction and return it with its secret."""
    if not scopes:
        raise ValueError("a key needs at least one scope")
    if robot_id is not None and set(scopes) != {Scope.UPLOAD}:
        raise ValueError("only upload keys can be bound to a robot")
    key_id = secrets.token_hex(6)
    secret = f"{KEY_PREFIX}_{key_id}_{secrets.token_urlsafe(32)}"
    ordered = tuple(sorted(set(scopes)))
    session.add(
        ApiKey(
            id=key_id,
            key_hash=hash_key(secret),
            scopes=[s.value for s in ordered],
            robot_id=robot_id,
            name=name,
        )
    )
    return NewKey(id=key_id, secret=secret, scopes=ordered, robot_id=robot_id)


def authenticate(session: Session, key: str) -> Principal | None:
    """The principal of a valid, unrevoked key, else None (unknown, malformed and revoked keys
    are not told apart)."""
    match = _KEY_PATTERN.fullmatch(key)
    if match is None:
        return None
    row = session.get(ApiKey, match.group(1))
    if row is None or row.revoked_at is not None:
        return None
    if not hmac.compare_digest(row.key_hash, hash_key(key)):
        return None
    return Principal(
        key_id=row.id, scopes=frozenset(Scope(s) for s in row.scopes), robot_id=row.robot_id
    )


def list_keys(session: Session) -> list[ApiKey]:
    return list(session.scalars(select(ApiKey).order_by(ApiKey.created_at, ApiKey.id)))


def revoke_key(session: Session, key_id: str) -> bool:
    """Revoke the key; False if there is no such key. Revoking twice keeps the first time."""
    row = session.get(ApiKey, key_id)
    if row is None:
        return False
    if row.revoked_at is None:
        row.revoked_at = datetime.now(UTC)
    return True
