"""Runs: upload a recording (which enqueues its calibration), read one run, list runs."""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from typing import Annotated

import anyio
from anyio import to_thread
from fastapi import APIRouter, Header, Query, Request, Response
from sqlalchemy.exc import IntegrityError

from pipeline import ResultDocument
from service import overrides, repository
from service.deps import CurrentKey, ReadKey, RobotIdPath, Services, ServicesDep, SessionDep
from service.models import Override, Result, Run, RunKind, RunStatus
from service.pagination import (
    PAGE_SIZE_DEFAULT,
    PAGE_SIZE_MAX,
    cursor_datetime,
    cursor_uuid,
    decode_cursor,
    encode_cursor,
)
from service.parameters import CursorQuery, SinceQuery, UntilQuery
from service.problem_details import (
    PROBLEM_RESPONSES,
    ApiError,
    Forbidden,
    IdempotencyKeyReused,
    InvalidHeader,
    Problem,
    RobotNotFound,
    RunNotFound,
)
from service.run_config import parse_run_config
from service.schemas import (
    ROBOT_ID_PATTERN,
    OverridePublic,
    RunPage,
    RunPublic,
    RunSummary,
    UploadInfo,
)
from service.uploads import StoredUpload, stream_to_storage

router = APIRouter(prefix="/v1", tags=["runs"], responses=PROBLEM_RESPONSES)

MAX_CONFIG_HEADER_CHARS = 16 * 1024

IdempotencyKeyHeader = Annotated[
    str | None,
    Header(
        alias="Idempotency-Key",
        min_length=1,
        max_length=255,
        pattern=r"^[\x21-\x7e]+$",
        description="Repeating it (for the same robot) returns the first run.",
    ),
]
ContentSha256Header = Annotated[
    str | None,
    Header(
        alias="X-Content-SHA256",
        pattern=r"^[0-9a-fA-F]{64}$",
        description="Hex SHA-256 of the body; a mismatch is refused (422).",
    ),
]
RunConfigHeader = Annotated[
    str | None,
    Header(
        alias="X-Fleetcal-Config",
        max_length=MAX_CONFIG_HEADER_CHARS,
        description="Calibration config as a JSON object (reference LiDAR, initial "
        "extrinsics, ...): a `PipelineConfig` without `verdict`; an invalid one is refused "
        "(422).",
    ),
]

_UPLOAD_BODY = {
    "requestBody": {
        "required": True,
        "description": "The recording's raw bytes: a .mcap, a ROS 2 .db3, a ROS 1 .bag, or a "
        ".zip/.tar/.tar.gz of a ROS 2 bag directory (recognised by magic bytes).",
        "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}},
    }
}


@router.post(
    "/robots/{robot_id}/runs",
    status_code=202,
    summary="Upload a calibration recording and queue its run",
    openapi_extra=_UPLOAD_BODY,
    responses={
        202: {
            "description": "Queued (or the first run of a repeated Idempotency-Key).",
            "headers": {
                "Location": {"description": "The run's URL.", "schema": {"type": "string"}}
            },
        }
    },
)
async def upload_run(
    robot_id: RobotIdPath,
    kind: Annotated[RunKind, Query(description="Why the robot is calibrated.")],
    request: Request,
    response: Response,
    principal: CurrentKey,
    services: ServicesDep,
    idempotency_key: IdempotencyKeyHeader = None,
    content_sha256: ContentSha256Header = None,
    config: RunConfigHeader = None,
) -> RunPublic:
    """Stream the body to storage (never whole in memory), check its size, SHA-256 and format,
    then record the run as `queued` in the same transaction as the upload."""
    if not principal.may_upload_for(robot_id):
        raise Forbidden(f"this key may not upload for robot {robot_id!r}")
    parsed_config = parse_run_config(config)
    declared_length = _content_length(request)
    settings = services.settings

    if idempotency_key is not None:
        first = await to_thread.run_sync(_find_first_run, services, robot_id, idempotency_key)
        if first is not None:
            return _replay(first, kind, content_sha256, response, services)
    if not settings.create_robots_on_upload:
        await to_thread.run_sync(_require_robot, services, robot_id)

    run_id = uuid.uuid4()
    stored = await _store(request, services, robot_id, run_id, declared_length, content_sha256)
    upload = repository.NewUpload(
        run_id=run_id,
        robot_id=robot_id,
        kind=kind,
        size=stored.size,
        sha256=stored.sha256,
        format=stored.format.value,
        storage_key=stored.key,
        idempotency_key=idempotency_key,
        config=parsed_config,
        max_attempts=settings.run_max_attempts,
    )
    return await _record_or_replay(services, upload, content_sha256, response)


async def _store(
    request: Request,
    services: Services,
    robot_id: str,
    run_id: uuid.UUID,
    declared_length: int | None,
    content_sha256: str | None,
) -> StoredUpload:
    """The body in storage under the run's key, once it passed every check (counted if not)."""
    try:
        return await stream_to_storage(
            request.stream(),
            services.storage,
            repository.recording_key(robot_id, run_id),
            max_bytes=services.settings.max_upload_bytes,
            declared_length=declared_length,
            expected_sha256=content_sha256,
        )
    except ApiError as err:
        services.metrics.uploads.labels(err.slug).inc()
        raise


async def _record_or_replay(
    services: Services,
    upload: repository.NewUpload,
    content_sha256: str | None,
    response: Response,
) -> RunPublic:
    """Record the stored upload's run; if that fails, the stored recording is deleted again,
    and a request with the same Idempotency-Key that won the race gets its run."""
    try:
        run = await to_thread.run_sync(_record, services, upload)
    except BaseException as err:
        with anyio.CancelScope(shield=True):
            await to_thread.run_sync(services.storage.delete, upload.storage_key)
        key = upload.idempotency_key
        if isinstance(err, IntegrityError) and key is not None:
            # Another request with the same key won the race: answer with its run.
            first = await to_thread.run_sync(_find_first_run, services, upload.robot_id, key)
            if first is not None:
                return _replay(first, upload.kind, content_sha256, response, services)
        if isinstance(err, repository.UnknownRobotError):
            raise RobotNotFound(f"robot {upload.robot_id!r} is not registered") from err
        raise
    services.metrics.uploads.labels("accepted").inc()
    services.metrics.upload_bytes.inc(upload.size)
    response.headers["Location"] = f"/v1/runs/{run.id}"
    return run_public(run, None)


@router.get("/runs/{run_id}", summary="A run: status, timings, attempts, result or error")
def get_run(run_id: uuid.UUID, principal: CurrentKey, session: SessionDep) -> RunPublic:
    found = repository.get_run(session, run_id)
    if found is None:
        raise RunNotFound(f"no run {run_id}")
    run, result = found
    if not principal.may_read_robot(run.robot_id):
        raise Forbidden("this key may not read this robot's runs")
    return run_public(run, result, overrides.overrides_of(session, [run.id])[run.id])


@router.get("/runs", summary="Runs, newest first, cursor-paginated")
def list_runs(
    _: ReadKey,
    session: SessionDep,
    robot_id: Annotated[str | None, Query(pattern=ROBOT_ID_PATTERN)] = None,
    status: RunStatus | None = None,
    passed: Annotated[
        bool | None, Query(description="Verdict; runs without a result never match.")
    ] = None,
    kind: RunKind | None = None,
    since: SinceQuery = None,
    until: UntilQuery = None,
    limit: Annotated[int, Query(ge=1, le=PAGE_SIZE_MAX)] = PAGE_SIZE_DEFAULT,
    cursor: CursorQuery = None,
) -> RunPage:
    after = None
    if cursor is not None:
        created, run_id = decode_cursor(cursor, "runs", cursor_datetime, cursor_uuid)
        after = (created, run_id)
    where = repository.RunFilter(
        robot_id=robot_id, status=status, kind=kind, passed=passed, since=since, until=until
    )
    rows = repository.list_runs(session, where, limit=limit + 1, after=after)
    items = [
        run_summary(row.run, row.passed, row.metric_error_final, row.accepted)
        for row in rows[:limit]
    ]
    next_cursor = None
    if len(rows) > limit:
        last = rows[limit - 1].run
        next_cursor = encode_cursor("runs", last.created_at, last.id)
    return RunPage(items=items, next_cursor=next_cursor)


# -- helpers ------------------------------------------------------------------------------------


def run_summary(
    run: Run | repository.RunColumns,
    passed: bool | None,
    metric_error_final: float | None,
    accepted: bool | None = None,
) -> RunSummary:
    return RunSummary(
        id=run.id,
        robot_id=run.robot_id,
        kind=run.kind,
        status=run.status,
        attempts=run.attempts,
        created_at=run.created_at,
        started_at=run.started_at,
        finished_at=run.finished_at,
        passed=passed,
        metric_error_final=metric_error_final,
        accepted=accepted,
    )


def run_public(run: Run, result: Result | None, audit: Sequence[Override] = ()) -> RunPublic:
    summary = run_summary(
        run,
        result.passed if result else None,
        result.metric_error_final if result else None,
        result.accepted if result else None,
    )
    return RunPublic(
        **summary.model_dump(),
        max_attempts=run.max_attempts,
        stage=run.stage,
        progress=run.progress,
        upload=UploadInfo(size=run.upload_size, sha256=run.upload_sha256, format=run.upload_format),
        idempotency_key=run.idempotency_key,
        config=run.config,
        result=ResultDocument.model_validate(result.document) if result else None,
        error=Problem.model_validate(run.error) if run.error else None,
        overrides=[OverridePublic.model_validate(row, from_attributes=True) for row in audit],
    )


def _content_length(request: Request) -> int | None:
    raw = request.headers.get("content-length")
    if raw is None:
        return None
    if not raw.isdigit():
        raise InvalidHeader(f"Content-Length {raw!r} is not a byte count")
    return int(raw)


def _find_first_run(
    services: Services, robot_id: str, key: str
) -> tuple[Run, Result | None] | None:
    with services.db.session() as session:
        run = repository.find_run_by_idempotency_key(session, robot_id, key)
        return None if run is None else repository.get_run(session, run.id)


def _replay(
    first: tuple[Run, Result | None],
    kind: RunKind,
    content_sha256: str | None,
    response: Response,
    services: Services,
) -> RunPublic:
    run, result = first
    if run.kind != kind or (
        content_sha256 is not None and content_sha256.lower() != run.upload_sha256
    ):
        raise IdempotencyKeyReused(
            f"this Idempotency-Key already named run {run.id} with a different "
            f"{'kind' if run.kind != kind else 'body'}; use a new key for a new upload",
            run_id=str(run.id),
        )
    services.metrics.uploads.labels("replayed").inc()
    response.headers["Location"] = f"/v1/runs/{run.id}"
    response.headers["Idempotent-Replayed"] = "true"
    return run_public(run, result)


def _require_robot(services: Services, robot_id: str) -> None:
    with services.db.session() as session:
        if repository.get_robot(session, robot_id) is None:
            raise RobotNotFound(
                f"robot {robot_id!r} is not registered; an admin registers it "
                "with PUT /v1/robots/{robot_id}"
            )


def _record(services: Services, upload: repository.NewUpload) -> Run:
    with services.db.transaction() as session:
        return repository.record_upload(
            session, upload, create_robot=services.settings.create_robots_on_upload
        )
