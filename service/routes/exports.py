"""Exports of a run's result: ROS 2 launch YAML, URDF snippet, extrinsics.yaml, and the
calibrated copy of its recording (made on request from the stored upload)."""

from __future__ import annotations

import shutil
import tempfile
import uuid
from http import HTTPStatus
from pathlib import Path
from typing import Annotated, Any

from anyio import to_thread
from fastapi import APIRouter, Query
from fastapi.responses import FileResponse, Response
from starlette.background import BackgroundTask

from pipeline import (
    FILE_NAMES,
    MEDIA_TYPES,
    ExportError,
    ExportFormat,
    PipelineError,
    calibrated_extrinsics,
    render,
)
from service.auth import Principal
from service.deps import CurrentKey, Services, ServicesDep
from service.models import Result, Run, RunStatus
from service.problem_details import PROBLEM_RESPONSES, ApiError
from service.routes.reports import readable_run

router = APIRouter(prefix="/v1/runs", tags=["exports"], responses=PROBLEM_RESPONSES)

# Recordings are recognised by their magic bytes; the suffix only helps a human in the scratch dir.
_SUFFIXES = {"mcap": ".mcap", "sqlite3": ".db3", "ros1": ".bag", "zip": ".zip", "tar.gz": ".tar.gz"}


class RunHasNoResultError(ApiError):
    slug = "run-has-no-result"
    title = "The run has no result yet"
    status = HTTPStatus.CONFLICT


class NotExportableError(ApiError):
    slug = "not-exportable"
    title = "The result cannot be exported"
    status = HTTPStatus.CONFLICT


class ExportFailedError(ApiError):
    slug = "export-failed"
    title = "The export could not be made"
    status = HTTPStatus.UNPROCESSABLE_ENTITY


_DESCRIPTION = """\
`tf-static`: a ROS 2 launch file (YAML) of `tf2_ros static_transform_publisher` nodes, one per
LiDAR (`ros2 launch tf_static.launch.yaml`). `urdf`: a URDF with a fixed joint base -> LiDAR for
each. `extrinsics`: `extrinsics.yaml`, per LiDAR its parent, child and
`[x, y, z, qx, qy, qz, qw]`. `recording`: the uploaded recording with `/tf_static` replaced by the
calibrated extrinsics (MCAP for ROS 2 uploads, `.bag` for ROS 1), for Foxglove or RViz.

A result whose verdict failed is refused (409) unless `allow_failed=true`; a result with a LiDAR
the data could not determine is always refused."""


@router.get(
    "/{run_id}/exports/{fmt}",
    summary="Export the run's calibration",
    description=_DESCRIPTION,
    response_class=Response,
    responses={
        200: {
            "description": "The export, as an attachment.",
            "content": {
                "application/yaml": {},
                "application/xml": {},
                "application/octet-stream": {},
            },
        }
    },
)
async def export_run(
    run_id: uuid.UUID,
    fmt: ExportFormat,
    principal: CurrentKey,
    services: ServicesDep,
    allow_failed: Annotated[
        bool, Query(description="Export a result whose verdict failed (at your own risk).")
    ] = False,
) -> Response:
    run, document = await to_thread.run_sync(_finished_run, services, principal, run_id)
    name = f"{run.robot_id}-{run.id.hex[:8]}-{FILE_NAMES[fmt]}"
    try:
        if fmt is not ExportFormat.RECORDING:
            text = render(
                document,
                fmt,
                allow_failed=allow_failed,
                source=f"robot {run.robot_id}, run {run.id}",
            )
            return Response(
                text,
                media_type=MEDIA_TYPES[fmt],
                headers={"Content-Disposition": f'attachment; filename="{name}"'},
            )
        extrinsics = calibrated_extrinsics(document, allow_failed=allow_failed)
    except ExportError as err:
        raise NotExportableError(str(err)) from err
    scratch = Path(tempfile.mkdtemp(prefix="fleetcal-export-"))
    try:
        path = await to_thread.run_sync(
            _calibrated_recording,
            services,
            run,
            scratch,
            {e.child: e.matrix() for e in extrinsics},
            str(document.get("base_frame") or "base_link"),
        )
    except BaseException:
        shutil.rmtree(scratch, ignore_errors=True)
        raise
    if path.suffix == ".bag":
        name = name.removesuffix(".mcap") + ".bag"
    return FileResponse(
        path,
        media_type=MEDIA_TYPES[fmt],
        filename=name,
        background=BackgroundTask(shutil.rmtree, scratch, ignore_errors=True),
    )


def _finished_run(
    services: Services, principal: Principal, run_id: uuid.UUID
) -> tuple[Run, dict[str, Any]]:
    with services.db.session() as session:
        run, result = readable_run(session, principal, run_id)
        return run, _document(run, result)


def _document(run: Run, result: Result | None) -> dict[str, Any]:
    if result is None:
        state = (
            "failed, see its error"
            if run.status is RunStatus.FAILED
            else f"{run.status.value}; try again once it has succeeded"
        )
        raise RunHasNoResultError(f"run {run.id} has no result: it is {state}")
    return dict(result.document)


def _calibrated_recording(
    services: Services,
    run: Run,
    scratch: Path,
    T_base_lidar: dict[str, Any],
    base_frame: str,
) -> Path:
    from pipeline.io import ReaderConfig, write_calibrated_recording

    upload = scratch / f"recording{_SUFFIXES.get(run.upload_format, '')}"
    services.storage.download(run.storage_key, upload)
    limits = ReaderConfig().archive
    try:
        written = write_calibrated_recording(
            upload,
            scratch / "calibrated",
            T_base_lidar,
            base_frame=base_frame,
            limits=limits,
            scratch_dir=scratch,
        )
    except PipelineError as err:
        raise ExportFailedError(f"cannot write the calibrated recording: {err}") from err
    finally:
        upload.unlink(missing_ok=True)
    return written.path
