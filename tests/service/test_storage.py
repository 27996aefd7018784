"""The storage contract on both back-ends, a local directory and an S3-compatible server (moto's
S3 server over HTTP, as MinIO would be): invisible until commit, nothing left after abort."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import uuid
from datetime import timedelta
from pathlib import Path

import pytest

from service.settings import Settings
from service.storage import LocalStorage, S3Storage, Storage, StorageError, make_storage

MIB = 1024 * 1024


def _s3(endpoint: str, *, bucket: str | None = None, part_size: int = 5 * MIB) -> S3Storage:
    settings = Settings(
        storage_url=f"s3://{bucket or 'b' + uuid.uuid4().hex[:12]}/fleet/eu",
        s3_endpoint_url=endpoint,
        s3_region="us-east-1",
        s3_part_size_bytes=part_size,
    )
    storage = make_storage(settings)
    assert isinstance(storage, S3Storage)
    if bucket is None:
        storage.client.create_bucket(Bucket=storage.bucket)
    return storage


@pytest.fixture(params=["local", "s3"])
def storage(request: pytest.FixtureRequest, tmp_path: Path) -> Storage:
    if request.param == "local":
        return make_storage(Settings(storage_url=(tmp_path / "objects").as_uri()))
    request.getfixturevalue("s3_env")
    return _s3(request.getfixturevalue("s3_endpoint"))


def _leftovers(storage: Storage) -> list[str]:
    """Everything that is not a committed object: partial files or open multipart uploads."""
    if isinstance(storage, LocalStorage):
        return [p.name for p in storage.temporary_uploads()]
    assert isinstance(storage, S3Storage)
    uploads = storage.client.list_multipart_uploads(Bucket=storage.bucket).get("Uploads", [])
    return [u["Key"] for u in uploads]


def _read(storage: Storage, key: str) -> bytes:
    with storage.open(key) as stream:
        return stream.read()


def test_an_upload_is_invisible_until_committed(storage: Storage, tmp_path: Path) -> None:
    data = bytes(range(256)) * (12 * MIB // 256)  # several S3 parts, several writes
    pending = storage.begin_upload("recordings/R1/run-1")
    for offset in range(0, len(data), MIB):
        pending.write(data[offset : offset + MIB])
        assert not storage.exists("recordings/R1/run-1")
    pending.commit()
    assert storage.exists("recordings/R1/run-1")
    assert _read(storage, "recordings/R1/run-1") == data
    target = tmp_path / "download.bin"
    storage.download("recordings/R1/run-1", target)
    assert target.read_bytes() == data
    assert _leftovers(storage) == []
    storage.delete("recordings/R1/run-1")
    assert not storage.exists("recordings/R1/run-1")


def test_a_small_upload_is_one_object(storage: Storage) -> None:
    pending = storage.begin_upload("recordings/R1/small")
    pending.write(b"tiny")
    pending.commit()
    assert _read(storage, "recordings/R1/small") == b"tiny"
    assert _leftovers(storage) == []


def test_abort_leaves_nothing(storage: Storage) -> None:
    pending = storage.begin_upload("recordings/R1/run-2")
    pending.write(b"x" * (6 * MIB))  # past one S3 part: a multipart upload is open
    pending.write(b"y" * MIB)
    pending.abort()
    pending.abort()  # idempotent
    assert not storage.exists("recordings/R1/run-2")
    assert _leftovers(storage) == []
    with pytest.raises(StorageError):
        pending.write(b"more")
    with pytest.raises(StorageError):
        pending.commit()


def test_stale_uploads_are_swept(storage: Storage) -> None:
    pending = storage.begin_upload("recordings/R1/abandoned")
    pending.write(b"z" * (6 * MIB))
    if isinstance(storage, LocalStorage):  # moto reports a fixed initiation date (2010)
        assert storage.sweep_stale_uploads(timedelta(hours=1)) == 0  # still fresh
    assert len(_leftovers(storage)) == 1
    assert storage.sweep_stale_uploads(timedelta(seconds=-5)) == 1
    assert _leftovers(storage) == []


def test_check_writable(storage: Storage) -> None:
    storage.check_writable()
    assert _leftovers(storage) == []


@pytest.mark.parametrize(
    "key", ["../escape", "/etc/passwd", "a//b", "a/./b", "a/../../b", "", "a\\b", "a/b/"]
)
def test_keys_that_could_escape_are_refused(storage: Storage, key: str) -> None:
    with pytest.raises(ValueError, match="storage key"):
        storage.begin_upload(key)


def test_reading_a_missing_object_is_a_storage_error(storage: Storage) -> None:
    with pytest.raises(StorageError):
        storage.open("recordings/none")


def test_s3_without_its_bucket_is_not_writable(s3_env: None, s3_endpoint: str) -> None:
    storage = _s3(s3_endpoint, bucket="missing-bucket")
    with pytest.raises(StorageError, match="cannot write"):
        storage.check_writable()
    with pytest.raises(StorageError):
        pending = storage.begin_upload("recordings/R1/x")
        pending.write(b"abc")
        pending.commit()


def test_s3_objects_live_under_the_prefix(s3_env: None, s3_endpoint: str) -> None:
    storage = _s3(s3_endpoint)
    pending = storage.begin_upload("recordings/R1/run")
    pending.write(b"data")
    pending.commit()
    listed = storage.client.list_objects_v2(Bucket=storage.bucket)["Contents"]
    assert [o["Key"] for o in listed] == ["fleet/eu/recordings/R1/run"]


def test_local_storage_defaults_under_the_data_dir(tmp_path: Path) -> None:
    storage = make_storage(Settings(data_dir=tmp_path / "state"))
    assert isinstance(storage, LocalStorage)
    assert storage.root == (tmp_path / "state" / "storage").resolve()
    assert (storage.root / ".tmp").is_dir()


def test_local_commit_is_an_atomic_rename(tmp_path: Path) -> None:
    storage = LocalStorage(tmp_path)
    pending = storage.begin_upload("recordings/R1/run")
    pending.write(b"abc")
    assert not (tmp_path / "recordings").exists()
    pending.commit()
    assert (tmp_path / "recordings" / "R1" / "run").read_bytes() == b"abc"
    assert storage.temporary_uploads() == []
    assert isinstance(storage.open("recordings/R1/run"), io.BufferedReader)


def test_keys_older_than_lists_the_objects_of_a_folder(storage: Storage) -> None:
    for key in ("recordings/R1/a", "recordings/R2/b", "reports/c", "recordings-old/d"):
        pending = storage.begin_upload(key)
        pending.write(b"x")
        pending.commit()
    assert sorted(storage.keys_older_than("recordings", timedelta(seconds=-5))) == [
        "recordings/R1/a",
        "recordings/R2/b",
    ]
    assert list(storage.keys_older_than("recordings", timedelta(hours=1))) == []  # still fresh
    assert list(storage.keys_older_than("nothing-here", timedelta(seconds=-5))) == []


_KILLED_WRITER = """
import sys, time
from pathlib import Path
from service.storage import LocalStorage
pending = LocalStorage(Path(sys.argv[1])).begin_upload("recordings/R1/run")
pending.write(b"half an upload")
print("writing", flush=True)
time.sleep(600)
"""


def test_a_killed_writer_s_upload_is_swept_at_once_and_a_live_one_is_kept(tmp_path: Path) -> None:
    root = tmp_path / "objects"
    writer = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(root)],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])},
    )
    assert writer.stdout is not None and writer.stdout.readline() == "writing\n"
    storage = LocalStorage(root)
    live = storage.begin_upload("recordings/R1/other")  # another process's, as far as locks go
    live.write(b"in progress")
    assert storage.sweep_stale_uploads(timedelta(hours=6)) == 0, "both writers are alive"
    writer.kill()
    writer.wait(30)
    assert len(storage.temporary_uploads()) == 2
    assert storage.sweep_stale_uploads(timedelta(hours=6)) == 1, "no 6 h wait for a dead writer"
    assert len(storage.temporary_uploads()) == 1
    live.commit()
    assert storage.exists("recordings/R1/other") and storage.temporary_uploads() == []


def test_an_upload_is_never_seen_unlocked_under_its_temporary_name(tmp_path: Path) -> None:
    storage = LocalStorage(tmp_path / "objects")
    pending = storage.begin_upload("recordings/R1/run")
    assert [p.suffix for p in (storage.root / ".tmp").iterdir()] == [".part"]
    assert storage.sweep_stale_uploads(timedelta(hours=6)) == 0
    pending.write(b"data")
    pending.commit()
    assert storage.sweep_stale_uploads(timedelta(hours=6)) == 0
    assert storage.open("recordings/R1/run").read() == b"data"
