"""`fleetcal export RESULT_OR_RUN --format tf-static|urdf|extrinsics|autoware|recording`: a
calibration in the form a robot's configuration takes, from a `result.json` on disk or a run on
the service. The file side (reading the document, rendering, the calibrated copy) is pipeline's;
this module adds the run id: the run's result, or its calibrated recording, over HTTP."""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from client.errors import EXIT_REFUSED, BadInputError, ClientError, RefusedError
from pipeline import ExportFormat, PipelineError

if TYPE_CHECKING:
    import httpx

_RUN_ID = re.compile(r"^[0-9a-fA-F]{8}-?([0-9a-fA-F]{4}-?){3}[0-9a-fA-F]{12}$")
_TIMEOUT_S = 600.0  # the service writes the calibrated recording before it answers

SourceArgument = Annotated[
    str,
    typer.Argument(
        metavar="RESULT_OR_RUN",
        help="a result.json (or a run document saved from GET /v1/runs/ID), or a run id on "
        "the service at --url",
    ),
]
FormatOption = Annotated[
    ExportFormat,
    typer.Option(
        "--format",
        "-f",
        help="tf-static: ROS 2 launch YAML of static_transform_publisher nodes; urdf: fixed "
        "joints base -> LiDAR; extrinsics: extrinsics.yaml; autoware: Autoware's "
        "sensor_kit_calibration.yaml layout; recording: the recording with /tf_static replaced",
    ),
]
OutOption = Annotated[
    Path | None,
    typer.Option(
        "--out",
        "-o",
        help="where to write (text formats: default stdout; recording: required, must not "
        "exist; a ROS 2 bag directory from --recording, else a file)",
    ),
]
RecordingOption = Annotated[
    Path | None,
    typer.Option(
        "--recording",
        help="the recording the result was calibrated from (format recording): its LiDARs, and "
        "its SHA-256 where the run's upload gives it, must be the result's (see --force); "
        "for a run id without it the service makes the copy from the run's upload",
    ),
]
AllowFailedOption = Annotated[
    bool, typer.Option("--allow-failed", help="export a result whose verdict failed")
]
ForceOption = Annotated[
    bool,
    typer.Option(
        "--force",
        help="write into a --recording that is not the one calibrated (other LiDARs or "
        "topics, another SHA-256 than the run's upload)",
    ),
]
UrlOption = Annotated[
    str, typer.Option("--url", envvar="FLEETCAL_URL", help="the fleetcal service")
]
ApiKeyOption = Annotated[
    str | None,
    typer.Option("--api-key", envvar="FLEETCAL_API_KEY", help="a key with the read scope"),
]


def register(app: typer.Typer) -> None:
    app.command("export")(export_command)


def export_command(
    source: SourceArgument,
    fmt: FormatOption,
    out: OutOption = None,
    recording: RecordingOption = None,
    allow_failed: AllowFailedOption = False,
    force: ForceOption = False,
    url: UrlOption = "http://127.0.0.1:8000",
    api_key: ApiKeyOption = None,
) -> None:
    """Export a calibration: ROS 2 tf_static launch file, URDF snippet, extrinsics.yaml, or a
    calibrated copy of the recording for Foxglove / RViz."""
    from pipeline import export_result, load_result, new_export_path

    with _user_errors():
        run_id = None if Path(source).exists() else _run_id(source)
        if run_id is None:
            document, upload_sha256 = load_result(Path(source))
        else:
            service = RunExports(url, api_key)
            document, upload_sha256 = service.result(run_id)
            if fmt is ExportFormat.RECORDING and recording is None:
                service.download_recording(run_id, new_export_path(out), allow_failed)
                _say(f"wrote {out}")
                return
        export_result(
            document,
            fmt,
            out=out,
            recording=recording,
            where=source if run_id is None else f"run {run_id}",
            upload_sha256=upload_sha256,
            allow_failed=allow_failed,
            force=force,
        )


def _say(message: str) -> None:
    typer.echo(message, err=True)


@contextmanager
def _user_errors() -> Iterator[None]:
    """The pipeline's and the client's errors as `error: <message>` and exit code 2 (a refusal
    by the service and an unreachable one alike: a person is there to read why)."""
    try:
        yield
    except (PipelineError, ClientError) as err:
        _say(f"error: {err}")
        raise typer.Exit(EXIT_REFUSED) from None


def _run_id(text: str) -> str:
    if not _RUN_ID.fullmatch(text):
        raise BadInputError(
            f"{text} is neither a file nor a run id; pass a result.json or a run's UUID"
        )
    return text


class RunExports:
    """The two calls `export` makes to the fleetcal API: a run's result, its calibrated
    recording. No retries: a person runs it and sees the answer at once."""

    def __init__(self, url: str, api_key: str | None) -> None:
        if not api_key:
            raise BadInputError(
                "a run id needs an API key with the read scope: pass --api-key or set "
                "FLEETCAL_API_KEY"
            )
        self.url = url.rstrip("/")
        self.headers = {"X-API-Key": api_key}

    def result(self, run_id: str) -> tuple[dict[str, Any], str | None]:
        """The run's result document and the SHA-256 of its upload."""
        import httpx

        from pipeline import result_from

        try:
            response = httpx.get(f"{self.url}/v1/runs/{run_id}", headers=self.headers, timeout=30)
        except httpx.HTTPError as err:
            raise self._unreachable(err) from None
        self._check(response)
        return result_from(response.json(), f"run {run_id}")

    def download_recording(self, run_id: str, out: Path, allow_failed: bool) -> None:
        """The service's calibrated copy of the run's upload, to `out` (whole or not at all)."""
        import httpx

        params = {"allow_failed": "true"} if allow_failed else {}
        path = f"/v1/runs/{run_id}/exports/recording"
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

    def _check(self, response: httpx.Response) -> None:
        if response.status_code == 200:
            return
        try:
            problem = response.json()
            detail = f"{problem['title']}: {problem['detail']}"
        except (ValueError, KeyError, TypeError):
            detail = response.text[:200] or response.reason_phrase
        raise RefusedError(f"the service answered {response.status_code} ({detail})")

    def _unreachable(self, err: Exception) -> ClientError:
        return ClientError(
            f"cannot reach the fleetcal service at {self.url} ({err}); start it with "
            "`fleetcal serve`, or pass --url"
        )
