"""`fleetcal export RESULT_OR_RUN --format tf-static|urdf|extrinsics|recording`: a calibration in
the form a robot's configuration takes, from a `result.json` on disk or a run on the service."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Annotated, Any

import typer

from pipeline.cli.common import progress, user_errors
from pipeline.errors import BadInputError, PipelineError
from pipeline.export import ExportFormat

_RUN_ID = re.compile(r"^[0-9a-fA-F]{8}-?([0-9a-fA-F]{4}-?){3}[0-9a-fA-F]{12}$")
_TIMEOUT_S = 600.0  # the service writes the calibrated recording before it answers


def register(app: typer.Typer) -> None:
    app.command("export")(export_command)


def export_command(
    source: Annotated[
        str,
        typer.Argument(
            metavar="RESULT_OR_RUN",
            help="a result.json (or a run document saved from GET /v1/runs/ID), or a run id on "
            "the service at --url",
        ),
    ],
    fmt: Annotated[
        ExportFormat,
        typer.Option(
            "--format",
            "-f",
            help="tf-static: ROS 2 launch YAML of static_transform_publisher nodes; urdf: fixed "
            "joints base -> LiDAR; extrinsics: extrinsics.yaml; autoware: Autoware's "
            "sensor_kit_calibration.yaml layout; recording: the recording with /tf_static replaced",
        ),
    ],
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            "-o",
            help="where to write (text formats: default stdout; recording: required, must not "
            "exist; a ROS 2 bag directory from --recording, else a file)",
        ),
    ] = None,
    recording: Annotated[
        Path | None,
        typer.Option(
            "--recording",
            help="the recording the result was calibrated from (format recording): its LiDARs, and "
            "its SHA-256 where the run's upload gives it, must be the result's (see --force); "
            "for a run id without it the service makes the copy from the run's upload",
        ),
    ] = None,
    allow_failed: Annotated[
        bool, typer.Option("--allow-failed", help="export a result whose verdict failed")
    ] = False,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="write into a --recording that is not the one calibrated (other LiDARs or "
            "topics, another SHA-256 than the run's upload)",
        ),
    ] = False,
    url: Annotated[
        str, typer.Option("--url", envvar="FLEETCAL_URL", help="the fleetcal service")
    ] = "http://127.0.0.1:8000",
    api_key: Annotated[
        str | None,
        typer.Option("--api-key", envvar="FLEETCAL_API_KEY", help="a key with the read scope"),
    ] = None,
) -> None:
    """Export a calibration: ROS 2 tf_static launch file, URDF snippet, extrinsics.yaml, or a
    calibrated copy of the recording for Foxglove / RViz."""
    from pipeline.export import calibrated_extrinsics, render

    with user_errors():
        run_id = None if Path(source).exists() else _run_id(source)
        service = _Service(url, api_key) if run_id is not None else None
        document, upload_sha256 = (
            service.result(run_id) if service and run_id else _load(Path(source))
        )
        where = f"run {run_id}" if run_id else str(source)
        if fmt is not ExportFormat.RECORDING:
            text = render(document, fmt, allow_failed=allow_failed, source=where)
            if out is None:
                typer.echo(text, nl=False)
            else:
                out.write_text(text, encoding="utf-8")
                progress(f"wrote {out}")
            return
        if out is None:
            raise BadInputError("--format recording needs --out PATH (a new path)")
        if out.exists():
            raise BadInputError(f"{out} already exists; choose a new --out path")
        if recording is not None:
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
        elif service is not None and run_id is not None:
            service.download(f"/v1/runs/{run_id}/exports/recording", out, allow_failed)
            progress(f"wrote {out}")
        else:
            raise BadInputError(
                "--format recording from a result.json needs --recording PATH, the recording it "
                "was calibrated from"
            )


def _run_id(text: str) -> str:
    if not _RUN_ID.fullmatch(text):
        raise BadInputError(
            f"{text} is neither a file nor a run id; pass a result.json or a run's UUID"
        )
    return text


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


def _load(path: Path) -> tuple[dict[str, Any], str | None]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise BadInputError(f"cannot read {path} as JSON ({err}); pass a result.json") from None
    return _result_of(data, str(path))


def _result_of(data: Any, where: str) -> tuple[dict[str, Any], str | None]:
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


class _Service:
    """The few calls `export` makes to the fleetcal API."""

    def __init__(self, url: str, api_key: str | None) -> None:
        if not api_key:
            raise BadInputError(
                "a run id needs an API key with the read scope: pass --api-key or set "
                "FLEETCAL_API_KEY"
            )
        self.url = url.rstrip("/")
        self.headers = {"X-API-Key": api_key}

    def result(self, run_id: str) -> tuple[dict[str, Any], str | None]:
        import httpx

        try:
            response = httpx.get(f"{self.url}/v1/runs/{run_id}", headers=self.headers, timeout=30)
        except httpx.HTTPError as err:
            raise self._unreachable(err) from None
        self._check(response)
        return _result_of(response.json(), f"run {run_id}")

    def download(self, path: str, out: Path, allow_failed: bool) -> None:
        import httpx

        params = {"allow_failed": "true"} if allow_failed else {}
        partial = out.with_name(out.name + ".part")
        try:
            with httpx.stream(
                "GET", self.url + path, headers=self.headers, params=params, timeout=_TIMEOUT_S
            ) as response:
                if response.status_code != 200:
                    response.read()
                    self._check(response)
                with partial.open("wb") as target:
                    for chunk in response.iter_bytes(1024 * 1024):
                        target.write(chunk)
            partial.replace(out)
        except httpx.HTTPError as err:
            raise self._unreachable(err) from None
        finally:
            partial.unlink(missing_ok=True)

    def _check(self, response: Any) -> None:
        if response.status_code == 200:
            return
        try:
            problem = response.json()
            detail = f"{problem['title']}: {problem['detail']}"
        except (ValueError, KeyError, TypeError):
            detail = response.text[:200] or response.reason_phrase
        message = f"the service answered {response.status_code} ({detail})"
        if response.status_code in (400, 404, 409, 422):
            raise BadInputError(message)
        raise PipelineError(message)

    def _unreachable(self, err: Exception) -> PipelineError:
        return PipelineError(
            f"cannot reach the fleetcal service at {self.url} ({err}); start it with "
            "`fleetcal serve`, or pass --url"
        )
