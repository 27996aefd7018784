"""The file side of `fleetcal export` and `fleetcal export-map`: a result document read from a
`result.json` (or a saved run document), written out as text (tf-static, urdf, extrinsics,
autoware) or as a calibrated copy of the recording it was calibrated from.

The command itself is `client/export.py`: it also takes a run id and fetches the run's result
from the service, which the numerical core must not do (it talks no HTTP).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import typer

from pipeline.cli.common import progress
from pipeline.errors import BadInputError
from pipeline.export import ExportFormat


def load_result(path: Path) -> tuple[dict[str, Any], str | None]:
    """The result document in the file at `path` and the SHA-256 of its recording where known
    (see `result_from`)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise BadInputError(f"cannot read {path} as JSON ({err}); pass a result.json") from None
    return result_from(data, str(path))


def result_from(data: Any, where: str) -> tuple[dict[str, Any], str | None]:
    """The result document, given it or a run document (`GET /v1/runs/{id}`) holding it, and the
    SHA-256 of the recording it calibrated where known (a run document's upload)."""
    sha256 = None
    if isinstance(data, dict) and "lidars" not in data and "status" in data:
        if not isinstance(data.get("result"), dict):
            raise BadInputError(
                f"{where}: the run is {data.get('status')} and has no result yet; export it "
                "once it has succeeded"
            )
        upload = data.get("upload")
        if isinstance(upload, dict) and isinstance(upload.get("sha256"), str):
            sha256 = upload["sha256"]
        data = data["result"]
    if not isinstance(data, dict):
        raise BadInputError(f"{where} is not a fleetcal result document")
    return data, sha256


def new_export_path(out: Path | None) -> Path:
    """`out`, which the calibrated recording is written to: it must be given and must not exist
    (a copy of a recording never overwrites anything)."""
    if out is None:
        raise BadInputError("--format recording needs --out PATH (a new path)")
    if out.exists():
        raise BadInputError(f"{out} already exists; choose a new --out path")
    return out


def export_result(
    document: dict[str, Any],
    fmt: ExportFormat,
    *,
    out: Path | None,
    recording: Path | None,
    where: str,
    upload_sha256: str | None = None,
    allow_failed: bool = False,
    force: bool = False,
) -> None:
    """Write `document` (calibrated from the recording `where` names) as `fmt`: a text format to
    `out` or stdout, or (`recording`) a calibrated copy of `recording` at the new path `out`."""
    from pipeline.export import render

    if fmt is not ExportFormat.RECORDING:
        text = render(document, fmt, allow_failed=allow_failed, source=where)
        if out is None:
            typer.echo(text, nl=False)
        else:
            out.write_text(text, encoding="utf-8")
            progress(f"wrote {out}")
        return
    out = new_export_path(out)
    if recording is None:
        raise BadInputError(
            "--format recording from a result.json needs --recording PATH, the recording it "
            "was calibrated from"
        )
    _write_calibrated_copy(document, recording, out, upload_sha256, allow_failed, force)


def _write_calibrated_copy(
    document: dict[str, Any],
    recording: Path,
    out: Path,
    upload_sha256: str | None,
    allow_failed: bool,
    force: bool,
) -> None:
    from pipeline.export import calibrated_extrinsics
    from pipeline.io.retag import write_calibrated_recording

    extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    _check_recording(document, recording, upload_sha256, force=force)
    written = write_calibrated_recording(
        recording,
        out,
        {edge.child: edge.matrix() for edge in extrinsics},
        base_frame=extrinsics[0].parent,
    )
    progress(
        f"wrote {written.path} ({written.format}, {written.messages} messages, "
        f"/tf_static: {', '.join(f'{e.parent}->{e.child}' for e in written.edges)})"
    )


def _check_recording(
    document: dict[str, Any], recording: Path, upload_sha256: str | None, *, force: bool
) -> None:
    """Refuse (unless `force`) a recording other than the one `document` calibrated; warn about
    what the copy leaves as recorded."""
    from pipeline.export import check_recording
    from pipeline.io.lidar_frames import lidar_frames

    sha256 = _sha256(recording) if upload_sha256 and recording.is_file() else None
    check = check_recording(
        document, lidar_frames(recording), sha256=sha256, calibrated_sha256=upload_sha256
    )
    if check.mismatches and not force:
        raise BadInputError(
            f"{recording} is not the recording this result calibrated: "
            f"{'; '.join(check.mismatches)}. Pass the recording it was calibrated from as "
            "--recording, or --force to write the calibration into this one anyway"
        )
    for line in (*check.mismatches, *check.notes):
        progress(f"warning: {recording}: {line}")


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        while chunk := stream.read(1024 * 1024):
            digest.update(chunk)
    return digest.hexdigest()
