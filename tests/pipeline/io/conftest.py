"""Recordings shared by the reader tests: one stop-and-go scene in every accepted format."""

from __future__ import annotations

import shutil
import tarfile
import zipfile
from pathlib import Path
from typing import Literal

import pytest

from pipeline.io.writer import WriterFormat
from tests.pipeline.io.recordings import Spec, Truth, write_recording

SCENE = Spec(stops=3)


def _zip(source: Path, target: Path) -> Path:
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(source.rglob("*")):
            archive.write(file, Path(source.name) / file.relative_to(source))
    return target


def _tar(source: Path, target: Path, mode: Literal["w", "w:gz"]) -> Path:
    with tarfile.open(target, mode) as archive:
        archive.add(source, arcname=source.name)
    return target


@pytest.fixture(scope="session")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Path], Truth]:
    """The same scene in every format `fleetcal inspect` accepts (some misleadingly named)."""
    root = tmp_path_factory.mktemp("recordings")
    mcap_dir, sqlite_dir, ros1 = root / "scene_mcap", root / "scene_sqlite", root / "scene.bag"
    truth = write_recording(mcap_dir, WriterFormat.ROS2_MCAP, SCENE)
    write_recording(sqlite_dir, WriterFormat.ROS2_SQLITE3, SCENE)
    write_recording(ros1, WriterFormat.ROS1, SCENE)
    bare = root / "bare"
    bare.mkdir()
    no_metadata = root / "no_metadata"
    no_metadata.mkdir()
    shutil.copy(mcap_dir / "scene_mcap.mcap", no_metadata / "part_0.mcap")
    paths = {
        "ros2-mcap-dir": mcap_dir,
        "ros2-sqlite3-dir": sqlite_dir,
        "ros1": ros1,
        "bare-mcap": Path(shutil.copy(mcap_dir / "scene_mcap.mcap", bare / "scene.mcap")),
        "bare-mcap-misnamed": Path(shutil.copy(mcap_dir / "scene_mcap.mcap", bare / "upload.bin")),
        "bare-db3": Path(shutil.copy(sqlite_dir / "scene_sqlite.db3", bare / "scene.db3")),
        "ros1-misnamed": Path(shutil.copy(ros1, bare / "upload.dat")),
        "ros2-dir-without-metadata": no_metadata,
        "zip": _zip(mcap_dir, root / "scene.zip"),
        "zip-sqlite3": _zip(sqlite_dir, root / "scene_sqlite.zip"),
        "tar": _tar(mcap_dir, root / "scene.tar", "w"),
        "tar.gz": _tar(mcap_dir, root / "scene.tgz.upload", "w:gz"),
    }

    return paths, truth


@pytest.fixture(scope="session")
def recordings(scene: tuple[dict[str, Path], Truth]) -> dict[str, Path]:
    return scene[0]


@pytest.fixture(scope="session")
def truth(scene: tuple[dict[str, Path], Truth]) -> Truth:
    return scene[1]
