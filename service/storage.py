"""Object storage for recordings behind one interface: a local directory (default) or an
S3-compatible bucket. Uploads are written aside and become visible only on `commit`.

Local: a temporary file under `.tmp/`, locked by its writer, fsynced and renamed into place. S3:
a multipart upload that is completed on commit (its parts are invisible until then) or aborted;
small objects are one PUT.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import time
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, Protocol, cast
from urllib.parse import unquote, urlsplit

from service.settings import Settings, check_storage_url

if TYPE_CHECKING:
    from mypy_boto3_s3 import S3Client

_KEY_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*(/[A-Za-z0-9][A-Za-z0-9._-]*)*$")


class StorageError(Exception):
    """The storage failed (unreachable, refused, misconfigured). Worth retrying later."""


class StorageFullError(StorageError):
    """The storage has no space left for the object."""


class PendingUpload(Protocol):
    """An object being written; invisible under its key until `commit`."""

    key: str

    def write(self, data: bytes) -> None: ...

    def commit(self) -> None: ...

    def abort(self) -> None:
        """Discard everything written; safe to call more than once and after a failed write."""


class Storage(Protocol):
    url: str

    def begin_upload(self, key: str) -> PendingUpload: ...

    def open(self, key: str) -> BinaryIO: ...

    def download(self, key: str, destination: Path) -> None: ...

    def exists(self, key: str) -> bool: ...

    def delete(self, key: str) -> None: ...

    def check_writable(self) -> None:
        """Write and remove a probe object; raise `StorageError` if that fails."""

    def sweep_stale_uploads(self, older_than: timedelta) -> int:
        """Remove uploads a killed process left behind; return how many."""

    def keys_older_than(self, prefix: str, older_than: timedelta) -> Iterator[str]:
        """Keys of the stored objects in the folder `prefix` (no trailing slash) last written
        more than `older_than` ago."""


def validate_key(key: str) -> str:
    """Refuse keys that could escape the storage root (`..`, absolute paths, odd characters)."""
    if not _KEY_PATTERN.fullmatch(key) or any(part in ("..", ".") for part in key.split("/")):
        raise ValueError(f"invalid storage key {key!r}")
    return key


def make_storage(settings: Settings) -> Storage:
    """The storage `settings.resolved_storage_url` names (`file://` or `s3://`)."""
    url = settings.resolved_storage_url
    check_storage_url(url)
    parts = urlsplit(url)
    if parts.scheme == "file":
        return LocalStorage(Path(unquote(parts.path)))
    import boto3  # heavy: only when S3 is configured
    from botocore.config import Config

    client = boto3.client(
        "s3",
        endpoint_url=settings.s3_endpoint_url,
        region_name=settings.s3_region,
        config=Config(retries={"max_attempts": 5, "mode": "standard"}),
    )
    return S3Storage(
        client, parts.netloc, parts.path.strip("/"), part_size=settings.s3_part_size_bytes
    )


# -- local directory ------------------------------------------------------------------------------


class LocalStorage:
    """Objects are files under `root`; uploads in progress live in `root/.tmp`."""

    def __init__(self, root: Path) -> None:
        self.root = root.resolve()
        self.url = self.root.as_uri()
        self._tmp = self.root / ".tmp"
        self._tmp.mkdir(parents=True, exist_ok=True)

    def path(self, key: str) -> Path:
        path = (self.root / validate_key(key)).resolve()
        if not path.is_relative_to(self.root) or path == self.root:
            raise ValueError(f"storage key {key!r} leaves the storage root")
        return path

    def begin_upload(self, key: str) -> _LocalUpload:
        return _LocalUpload(self, key)

    def open(self, key: str) -> BinaryIO:
        try:
            return self.path(key).open("rb")
        except OSError as err:
            raise StorageError(f"cannot read {key}: {err.strerror}") from err

    def download(self, key: str, destination: Path) -> None:
        with self.open(key) as source, destination.open("wb") as target:
            shutil.copyfileobj(source, target, 1024 * 1024)

    def exists(self, key: str) -> bool:
        return self.path(key).is_file()

    def delete(self, key: str) -> None:
        self.path(key).unlink(missing_ok=True)

    def check_writable(self) -> None:
        probe = self._tmp / f"probe-{uuid.uuid4().hex}"
        try:
            probe.write_bytes(b"ok")
            probe.unlink()
        except OSError as err:
            raise StorageError(f"cannot write to {self._tmp}: {err.strerror}") from err

    def sweep_stale_uploads(self, older_than: timedelta) -> int:
        """Remove the uploads no process is writing (their writer holds a lock on the file, which
        the system drops when the process dies, however it dies), at any age; and, as before,
        those still locked but untouched for `older_than` (a writer hung that long). Safe with
        several API processes on one storage directory: another process's upload stays locked."""
        cutoff = time.time() - older_than.total_seconds()
        removed = 0
        for part in self._tmp.glob("*.part"):
            with contextlib.suppress(FileNotFoundError):
                if not _locked(part) or part.stat().st_mtime < cutoff:
                    part.unlink()
                    removed += 1
        for creating in self._tmp.glob("*.creating"):  # a writer killed between two calls
            with contextlib.suppress(FileNotFoundError):
                if creating.stat().st_mtime < cutoff:
                    creating.unlink()
        return removed

    def keys_older_than(self, prefix: str, older_than: timedelta) -> Iterator[str]:
        cutoff = time.time() - older_than.total_seconds()
        base = self.root / validate_key(prefix)
        for path in sorted(base.rglob("*")) if base.is_dir() else []:
            with contextlib.suppress(FileNotFoundError):
                if path.is_file() and path.stat().st_mtime < cutoff:
                    yield path.relative_to(self.root).as_posix()

    def temporary_uploads(self) -> list[Path]:
        """Uploads in progress or left behind (tests and the reaper look here)."""
        return sorted(self._tmp.glob("*.part"))


class _LocalUpload:
    def __init__(self, storage: LocalStorage, key: str) -> None:
        self.key = key
        self._final = storage.path(key)
        name = uuid.uuid4().hex
        self._part = storage._tmp / f"{name}.part"
        # Locked before it is named `.part`, so that a sweep never finds it unlocked while alive.
        creating = storage._tmp / f"{name}.creating"
        try:
            file = creating.open("xb")
        except OSError as err:
            raise _os_error(err, f"cannot create {self._part}") from err
        try:
            fcntl.flock(file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.replace(creating, self._part)
        except OSError as err:
            file.close()
            creating.unlink(missing_ok=True)
            raise _os_error(err, f"cannot create {self._part}") from err
        self._file: BinaryIO | None = file

    def write(self, data: bytes) -> None:
        if self._file is None:
            raise StorageError("upload already committed or aborted")
        try:
            self._file.write(data)
        except OSError as err:
            self.abort()
            raise _os_error(err, "cannot write the upload") from err

    def commit(self) -> None:
        if self._file is None:
            raise StorageError("upload already committed or aborted")
        file, self._file = self._file, None
        try:
            file.flush()
            # Durable before visible: a crash after the run is recorded must not lose the bytes.
            os.fsync(file.fileno())
            self._final.parent.mkdir(parents=True, exist_ok=True)
            # Renamed while still open (so still locked): a sweep never sees it unlocked.
            os.replace(self._part, self._final)
            file.close()
            _fsync_dir(self._final.parent)
        except OSError as err:
            file.close()
            self._part.unlink(missing_ok=True)
            raise _os_error(err, f"cannot store {self.key}") from err

    def abort(self) -> None:
        if self._file is not None:
            file, self._file = self._file, None
            with contextlib.suppress(OSError):
                file.close()
        self._part.unlink(missing_ok=True)


def _locked(path: Path) -> bool:
    """Whether a process holds the lock on `path` (a `_LocalUpload` being written)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing drops the lock this probe may have taken
    return False


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _os_error(err: OSError, what: str) -> StorageError:
    import errno

    if err.errno in (errno.ENOSPC, errno.EDQUOT):
        return StorageFullError(f"{what}: no space left on the storage")
    return StorageError(f"{what}: {err.strerror}")


# -- S3-compatible --------------------------------------------------------------------------------


class S3Storage:
    """Objects in `bucket` under `prefix/`, through boto3 (AWS, MinIO, Ceph, ...)."""

    def __init__(
        self, client: S3Client, bucket: str, prefix: str = "", *, part_size: int = 16 * 1024**2
    ) -> None:
        self.client = client
        self.bucket = bucket
        self.prefix = f"{prefix}/" if prefix else ""
        self.part_size = part_size
        self.url = f"s3://{bucket}/{prefix}".rstrip("/")

    def object_key(self, key: str) -> str:
        return self.prefix + validate_key(key)

    def begin_upload(self, key: str) -> _S3Upload:
        return _S3Upload(self, key)

    def open(self, key: str) -> BinaryIO:
        from botocore.exceptions import BotoCoreError, ClientError

        try:
            response = self.client.get_object(Bucket=self.bucket, Key=self.object_key(key))
        except (BotoCoreError, ClientError) as err:
            raise StorageError(f"cannot read {key} from {self.url}: {err}") from err
        return cast(BinaryIO, response["Body"])

    def download(self, key: str, destination: Path) -> None:
        from botocore.exceptions import BotoCoreError, ClientError

        try:
            self.client.download_file(self.bucket, self.object_key(key), str(destination))
        except (BotoCoreError, ClientError) as err:
            raise StorageError(f"cannot download {key} from {self.url}: {err}") from err

    def exists(self, key: str) -> bool:
        from botocore.exceptions import ClientError

        try:
            self.client.head_object(Bucket=self.bucket, Key=self.object_key(key))
        except ClientError as err:
            if err.response.get("Error", {}).get("Code") in ("404", "NoSuchKey", "NotFound"):
                return False
            raise StorageError(f"cannot check {key} in {self.url}: {err}") from err
        return True

    def delete(self, key: str) -> None:
        from botocore.exceptions import BotoCoreError, ClientError

        try:
            self.client.delete_object(Bucket=self.bucket, Key=self.object_key(key))
        except (BotoCoreError, ClientError) as err:
            raise StorageError(f"cannot delete {key} from {self.url}: {err}") from err

    def check_writable(self) -> None:
        from botocore.exceptions import BotoCoreError, ClientError

        probe = f"{self.prefix}.probe/{uuid.uuid4().hex}"
        try:
            self.client.put_object(Bucket=self.bucket, Key=probe, Body=b"ok")
            self.client.delete_object(Bucket=self.bucket, Key=probe)
        except (BotoCoreError, ClientError) as err:
            raise StorageError(f"cannot write to {self.url}: {err}") from err

    def keys_older_than(self, prefix: str, older_than: timedelta) -> Iterator[str]:
        from botocore.exceptions import BotoCoreError, ClientError

        cutoff = datetime.now(UTC) - older_than
        paginator = self.client.get_paginator("list_objects_v2")
        try:
            folder = self.object_key(prefix) + "/"
            for page in paginator.paginate(Bucket=self.bucket, Prefix=folder):
                for item in page.get("Contents", []):
                    if item["LastModified"] < cutoff:
                        yield item["Key"][len(self.prefix) :]
        except (BotoCoreError, ClientError) as err:
            raise StorageError(f"cannot list {self.url}: {err}") from err

    def sweep_stale_uploads(self, older_than: timedelta) -> int:
        cutoff = datetime.now(UTC) - older_than
        removed = 0
        paginator = self.client.get_paginator("list_multipart_uploads")
        for page in paginator.paginate(Bucket=self.bucket, Prefix=self.prefix):
            for upload in page.get("Uploads", []):
                if upload["Initiated"] < cutoff:
                    self.client.abort_multipart_upload(
                        Bucket=self.bucket, Key=upload["Key"], UploadId=upload["UploadId"]
                    )
                    removed += 1
        return removed


class _S3Upload:
    def __init__(self, storage: S3Storage, key: str) -> None:
        self.key = key
        self._storage = storage
        self._object_key = storage.object_key(key)
        self._buffer = bytearray()
        self._upload_id: str | None = None
        self._parts: list[dict[str, object]] = []
        self._done = False

    def write(self, data: bytes) -> None:
        if self._done:
            raise StorageError("upload already committed or aborted")
        self._buffer += data
        while len(self._buffer) >= self._storage.part_size:
            self._send_part(self._storage.part_size)

    def _send_part(self, size: int) -> None:
        from botocore.exceptions import BotoCoreError, ClientError

        client, bucket = self._storage.client, self._storage.bucket
        body = bytes(self._buffer[:size])
        try:
            if self._upload_id is None:
                self._upload_id = client.create_multipart_upload(
                    Bucket=bucket, Key=self._object_key
                )["UploadId"]
            number = len(self._parts) + 1
            response = client.upload_part(
                Bucket=bucket,
                Key=self._object_key,
                Body=body,
                PartNumber=number,
                UploadId=self._upload_id,
            )
        except (BotoCoreError, ClientError) as err:
            self.abort()
            raise StorageError(f"cannot upload {self.key} to {self._storage.url}: {err}") from err
        self._parts.append({"PartNumber": number, "ETag": response["ETag"]})
        del self._buffer[:size]

    def commit(self) -> None:
        from botocore.exceptions import BotoCoreError, ClientError

        if self._done:
            raise StorageError("upload already committed or aborted")
        client, bucket = self._storage.client, self._storage.bucket
        try:
            if self._upload_id is None:
                client.put_object(Bucket=bucket, Key=self._object_key, Body=bytes(self._buffer))
            else:
                if self._buffer:
                    self._send_part(len(self._buffer))
                client.complete_multipart_upload(
                    Bucket=bucket,
                    Key=self._object_key,
                    UploadId=self._upload_id,
                    MultipartUpload={"Parts": self._parts},  # type: ignore[typeddict-item]
                )
        except (BotoCoreError, ClientError) as err:
            self.abort()
            raise StorageError(f"cannot store {self.key} in {self._storage.url}: {err}") from err
        self._done = True
        self._buffer.clear()

    def abort(self) -> None:
        from botocore.exceptions import BotoCoreError, ClientError

        self._done = True
        self._buffer.clear()
        if self._upload_id is not None:
            upload_id, self._upload_id = self._upload_id, None
            with contextlib.suppress(BotoCoreError, ClientError):
                self._storage.client.abort_multipart_upload(
                    Bucket=self._storage.bucket, Key=self._object_key, UploadId=upload_id
                )
