"""The data layer: every query and write the API and the workers make, on a caller's `Session`.

Functions never commit: the caller owns the transaction (`Database.transaction()`), so an upload's
robot, run and queue entry, or a result with its extrinsics and final status, land together.
"""

from __future__ import annotations

import contextlib
import json
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from pydantic import ValidationError
from sqlalchemy import case, func, select, true, tuple_, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session, aliased

from pipeline import ResultDocument
from service import outbox
from service.models import (
    EventType,
    LidarExtrinsic,
    Result,
    Robot,
    Run,
    RunKind,
    RunStatus,
    ToleranceProfile,
)


class RepositoryError(Exception):
    """Base of the data layer's errors."""


class UnknownRobotError(RepositoryError):
    pass


class UnknownRunError(RepositoryError):
    pass


class LeaseLostError(RepositoryError):
    """The run is no longer held by this worker (its lease expired and another took it over)."""


class RunFinishedError(RepositoryError):
    """The run already has its final status; a retry must not write a second result."""


class InvalidResultError(RepositoryError, ValueError):
    """The result document does not follow the `result.json` contract."""


class OverrideConflictError(RepositoryError):
    """The override would change nothing (accepting an accepted result, ...) or cannot be used."""


# -- robots -------------------------------------------------------------------------------------


def get_robot(session: Session, robot_id: str) -> Robot | None:
    return session.get(Robot, robot_id)


def put_robot(
    session: Session, robot_id: str, *, model: str | None, metadata: dict[str, Any]
) -> tuple[Robot, bool]:
    """Create or replace a robot's model and metadata; returns (robot, created)."""
    robot = session.get(Robot, robot_id)
    created = robot is None
    if robot is None:
        robot = Robot(id=robot_id, model=model, meta=metadata)
        session.add(robot)
    else:
        robot.model, robot.meta = model, metadata
    session.flush()
    return robot, created


def _insert_robot_if_absent(session: Session, robot_id: str) -> None:
    """Two first uploads of a new robot may race (PostgreSQL): the second must not fail."""
    dialect = session.get_bind().dialect.name
    insert_: Any = {"postgresql": postgresql.insert, "sqlite": sqlite.insert}[dialect]
    now = datetime.now(UTC)
    session.execute(
        insert_(Robot)
        .values(id=robot_id, meta={}, created_at=now, updated_at=now)
        .on_conflict_do_nothing(index_elements=[Robot.id])
    )


def list_robots(session: Session, *, limit: int, after_id: str | None) -> list[Robot]:
    stmt = select(Robot).order_by(Robot.id).limit(limit)
    if after_id is not None:
        stmt = stmt.where(Robot.id > after_id)
    return list(session.scalars(stmt))


# -- runs ---------------------------------------------------------------------------------------


def find_run_by_idempotency_key(session: Session, robot_id: str, key: str) -> Run | None:
    return session.scalar(select(Run).where(Run.robot_id == robot_id, Run.idempotency_key == key))


RECORDINGS = "recordings"
"""The storage folder of uploaded recordings: `recordings/{robot_id}/{run_id}`."""


def recording_key(robot_id: str, run_id: uuid.UUID) -> str:
    return f"{RECORDINGS}/{robot_id}/{run_id}"


def unreferenced_recordings(session: Session, keys: list[str]) -> list[str]:
    """The recording keys among `keys` that no run points at (found by run id, the key's last
    part). A key not ending in a run id is not one this service wrote, and is never returned."""
    by_run: dict[uuid.UUID, str] = {}
    for key in keys:
        with contextlib.suppress(ValueError):
            by_run[uuid.UUID(key.rsplit("/", 1)[-1])] = key
    run_ids = list(by_run)
    orphans = []
    for start in range(0, len(run_ids), 500):
        batch = run_ids[start : start + 500]
        rows = session.execute(select(Run.id, Run.storage_key).where(Run.id.in_(batch)))
        stored = {run_id: key for run_id, key in rows}
        orphans += [by_run[run_id] for run_id in batch if stored.get(run_id) != by_run[run_id]]
    return orphans


@dataclass(frozen=True)
class NewUpload:
    """What the upload endpoint knows once the recording is safely in storage."""

    run_id: uuid.UUID
    robot_id: str
    kind: RunKind
    size: int
    sha256: str
    format: str
    storage_key: str
    idempotency_key: str | None
    config: dict[str, Any] | None
    max_attempts: int


def record_upload(session: Session, upload: NewUpload, *, create_robot: bool) -> Run:
    """Insert the run (status `queued`: this is the enqueue), creating the robot if allowed.

    Raises `UnknownRobotError`, or `IntegrityError` when the idempotency key was taken meanwhile.
    """
    if session.get(Robot, upload.robot_id) is None:
        if not create_robot:
            raise UnknownRobotError(upload.robot_id)
        _insert_robot_if_absent(session, upload.robot_id)
    now = datetime.now(UTC)
    run = Run(
        id=upload.run_id,
        robot_id=upload.robot_id,
        kind=upload.kind,
        status=RunStatus.QUEUED,
        upload_size=upload.size,
        upload_sha256=upload.sha256,
        upload_format=upload.format,
        storage_key=upload.storage_key,
        idempotency_key=upload.idempotency_key,
        config=upload.config,
        attempts=0,
        max_attempts=upload.max_attempts,
        available_at=now,
        created_at=now,
        updated_at=now,
    )
    session.add(run)
    session.flush()
    return run


def get_run(session: Session, run_id: uuid.UUID) -> tuple[Run, Result | None] | None:
    row = session.execute(
        select(Run, Result).outerjoin(Result, Result.run_id == Run.id).where(Run.id == run_id)
    ).first()
    return None if row is None else (row[0], row[1])


@dataclass(frozen=True)
class RunFilter:
    robot_id: str | None = None
    status: RunStatus | None = None
    kind: RunKind | None = None
    passed: bool | None = None
    since: datetime | None = None
    until: datetime | None = None


@dataclass(frozen=True, slots=True)
class RunColumns:
    """What a listing shows of a run: plain columns, no ORM object (listings stay cheap)."""

    id: uuid.UUID
    robot_id: str
    kind: RunKind
    status: RunStatus
    attempts: int
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None


@dataclass(frozen=True, slots=True)
class RunRow:
    run: RunColumns
    passed: bool | None
    metric_error_final: float | None
    accepted: bool | None = None


_RUN_COLUMNS = (
    Run.id,
    Run.robot_id,
    Run.kind,
    Run.status,
    Run.attempts,
    Run.created_at,
    Run.started_at,
    Run.finished_at,
)


def list_runs(
    session: Session, where: RunFilter, *, limit: int, after: tuple[datetime, uuid.UUID] | None
) -> list[RunRow]:
    """Runs newest first, keyset-paged on (created_at, id): `after` is the last row seen."""
    stmt = (
        select(*_RUN_COLUMNS, Result.passed, Result.metric_error_final, Result.accepted)
        .outerjoin(Result, Result.run_id == Run.id)
        .order_by(Run.created_at.desc(), Run.id.desc())
        .limit(limit)
    )
    if where.robot_id is not None:
        stmt = stmt.where(Run.robot_id == where.robot_id)
    if where.status is not None:
        stmt = stmt.where(Run.status == where.status)
    if where.kind is not None:
        stmt = stmt.where(Run.kind == where.kind)
    if where.passed is not None:
        stmt = stmt.where(Result.passed.is_(where.passed))
    if where.since is not None:
        stmt = stmt.where(Run.created_at >= where.since)
    if where.until is not None:
        stmt = stmt.where(Run.created_at < where.until)
    if after is not None:
        stmt = stmt.where(tuple_(Run.created_at, Run.id) < tuple_(*after))
    return [
        RunRow(
            RunColumns(id_, robot_id, kind, status, attempts, created, started, finished),
            passed,
            final,
            accepted,
        )
        for (
            id_,
            robot_id,
            kind,
            status,
            attempts,
            created,
            started,
            finished,
            passed,
            final,
            accepted,
        ) in session.connection().execute(stmt).all()
    ]


def latest_run(session: Session, robot_id: str) -> RunRow | None:
    rows = list_runs(session, RunFilter(robot_id=robot_id), limit=1, after=None)
    return rows[0] if rows else None


# -- results ------------------------------------------------------------------------------------


def store_result(
    session: Session, run_id: uuid.UUID, document: dict[str, Any], *, lease_owner: str | None = None
) -> Result:
    """Write a run's result, its per-LiDAR extrinsics rows, and its final status `succeeded`.

    `succeeded` means the calibration ran to the end; whether it passed is the verdict in the
    result. With `lease_owner`, the run must still be `running` under that owner
    (`LeaseLostError` otherwise). A run already finished raises `RunFinishedError`, so a retried
    worker never writes a second result. LiDARs without a `calibrated` pose (undetermined by the
    data) keep their entry in the document but get no extrinsics row.
    """
    parsed = _result_document(document)
    run = _lock_run(session, run_id, lease_owner)
    if session.get(Result, run_id) is not None:
        raise RunFinishedError(f"run {run_id} already has a result")
    now = datetime.now(UTC)
    passed = parsed.verdict.passed
    result = Result(
        run_id=run.id,
        robot_id=run.robot_id,
        document=document,
        passed=passed,
        accepted=passed,
        metric_error_initial=parsed.metric_error.initial,
        metric_error_final=parsed.metric_error.final,
        pipeline_version=parsed.pipeline_version,
        config_hash=parsed.config_hash,
        measured_at=run.created_at,
        created_at=now,
    )
    session.add(result)
    session.flush()  # the extrinsics rows refer to it
    session.add_all(_extrinsic_rows(run, parsed))
    _finish(run, RunStatus.SUCCEEDED, now, error=None)
    outbox.enqueue_events(session, run, outbox.result_events(result))
    session.flush()
    return result


def _result_document(document: dict[str, Any]) -> ResultDocument:
    """`document` as the `result.json` model, or `InvalidResultError` saying what is wrong."""
    try:
        json.dumps(document, allow_nan=False)
    except ValueError as err:
        raise InvalidResultError(
            "result document holds NaN or infinity; a failure must be a "
            "failed check, never a non-finite number"
        ) from err
    except TypeError as err:
        raise InvalidResultError(f"result document is not JSON: {err}") from err
    try:
        return ResultDocument.model_validate(document)
    except ValidationError as err:
        raise InvalidResultError(f"result document does not follow result.json: {err}") from err


def _extrinsic_rows(run: Run, parsed: ResultDocument) -> list[LidarExtrinsic]:
    """One row per calibrated LiDAR, in frame order: the series of history and drift."""
    passed = parsed.verdict.passed
    rows = []
    for frame, lidar in sorted(parsed.lidars.items()):
        pose = lidar.calibrated
        if pose is None:
            continue
        (tx, ty, tz), (qx, qy, qz, qw) = pose.translation, pose.rotation_xyzw
        rows.append(
            LidarExtrinsic(
                run_id=run.id,
                robot_id=run.robot_id,
                frame=frame,
                measured_at=run.created_at,
                passed=passed,
                accepted=passed,
                is_reference=frame == parsed.reference_frame,
                tx=tx,
                ty=ty,
                tz=tz,
                qx=qx,
                qy=qy,
                qz=qz,
                qw=qw,
                stddev=lidar.stddev.model_dump(mode="json"),
            )
        )
    return rows


def fail_run(
    session: Session, run_id: uuid.UUID, problem: dict[str, Any], *, lease_owner: str | None = None
) -> Run:
    """Mark the run `failed` with `problem`, an RFC 9457 document (`problem_details`)."""
    run = _lock_run(session, run_id, lease_owner)
    _finish(run, RunStatus.FAILED, datetime.now(UTC), error=problem)
    outbox.enqueue_events(session, run, [(EventType.RUN_FAILED, {"error": problem})])
    session.flush()
    return run


def _lock_run(session: Session, run_id: uuid.UUID, lease_owner: str | None) -> Run:
    run = session.get(Run, run_id, with_for_update=True, populate_existing=True)
    if run is None:
        raise UnknownRunError(f"no run {run_id}")
    if run.status in (RunStatus.SUCCEEDED, RunStatus.FAILED):
        raise RunFinishedError(f"run {run_id} is already {run.status.value}")
    if lease_owner is not None and (
        run.status != RunStatus.RUNNING or run.lease_owner != lease_owner
    ):
        raise LeaseLostError(f"run {run_id} is not held by {lease_owner} any more")
    return run


def _finish(run: Run, status: RunStatus, now: datetime, *, error: dict[str, Any] | None) -> None:
    run.status = status
    run.finished_at = now
    run.error = error
    run.lease_owner = None
    run.lease_expires_at = None
    if status == RunStatus.SUCCEEDED:
        run.progress = 1.0


def latest_calibration(session: Session, robot_id: str) -> Result | None:
    """The newest accepted result of the robot (by upload time): passed and not rejected, or
    accepted by an operator despite its verdict."""
    return session.scalar(
        select(Result)
        .where(Result.robot_id == robot_id, Result.accepted.is_(True))
        .order_by(Result.measured_at.desc(), Result.run_id.desc())
        .limit(1)
    )


@dataclass(frozen=True, slots=True)
class ExtrinsicPoint:
    """One LiDAR's calibrated `T_base_lidar` from one run (a history point)."""

    id: int
    run_id: uuid.UUID
    frame: str
    measured_at: datetime
    passed: bool
    accepted: bool
    is_reference: bool
    translation: tuple[float, float, float]
    rotation_xyzw: tuple[float, float, float, float]
    stddev: dict[str, Any] | None


_E = LidarExtrinsic
_POINT_COLUMNS = (
    _E.id,
    _E.run_id,
    _E.frame,
    _E.measured_at,
    _E.passed,
    _E.accepted,
    _E.is_reference,
    _E.tx,
    _E.ty,
    _E.tz,
    _E.qx,
    _E.qy,
    _E.qz,
    _E.qw,
    _E.stddev,
)


def _point(columns: Sequence[Any]) -> ExtrinsicPoint:
    """An `ExtrinsicPoint` from the values of `_POINT_COLUMNS`, in their order."""
    id_, run_id, frame, at, passed, accepted, ref, tx, ty, tz, qx, qy, qz, qw, sd = columns
    return ExtrinsicPoint(
        id_, run_id, frame, at, passed, accepted, ref, (tx, ty, tz), (qx, qy, qz, qw), sd
    )


def _points(session: Session, stmt: Any) -> list[ExtrinsicPoint]:
    # Columns only: the Core connection skips the ORM's row loading, a third of the cost.
    return [_point(row) for row in session.connection().execute(stmt).all()]


def extrinsics_of(session: Session, run_id: uuid.UUID) -> list[ExtrinsicPoint]:
    return _points(session, select(*_POINT_COLUMNS).where(_E.run_id == run_id).order_by(_E.frame))


def history(
    session: Session,
    robot_id: str,
    *,
    frame: str | None,
    passed: bool | None,
    since: datetime | None,
    accepted: bool | None = None,
    until: datetime | None,
    limit: int,
    after: tuple[datetime, int] | None,
) -> list[ExtrinsicPoint]:
    """Per-LiDAR extrinsics oldest first, keyset-paged on (measured_at, id)."""
    stmt = (
        select(*_POINT_COLUMNS)
        .where(LidarExtrinsic.robot_id == robot_id)
        .order_by(LidarExtrinsic.measured_at, LidarExtrinsic.id)
        .limit(limit)
    )
    if frame is not None:
        stmt = stmt.where(LidarExtrinsic.frame == frame)
    if passed is not None:
        stmt = stmt.where(LidarExtrinsic.passed.is_(passed))
    if accepted is not None:
        stmt = stmt.where(LidarExtrinsic.accepted.is_(accepted))
    if since is not None:
        stmt = stmt.where(LidarExtrinsic.measured_at >= since)
    if until is not None:
        stmt = stmt.where(LidarExtrinsic.measured_at < until)
    if after is not None:
        stmt = stmt.where(tuple_(LidarExtrinsic.measured_at, LidarExtrinsic.id) > tuple_(*after))
    return _points(session, stmt)


# -- the fleet ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RobotColumns:
    id: str
    model: str | None
    metadata: dict[str, Any]
    created_at: datetime
    updated_at: datetime


@dataclass(frozen=True, slots=True)
class AcceptedRow:
    """A robot's newest passed result: the calibration it should be using."""

    run_id: uuid.UUID
    measured_at: datetime
    metric_error_final: float | None


@dataclass(frozen=True, slots=True)
class FleetRow:
    robot: RobotColumns
    latest: RunRow | None
    accepted: AcceptedRow | None


@dataclass(frozen=True, slots=True)
class FleetTotals:
    """Counts over the whole fleet, by each robot's latest run (not over one page)."""

    robots: int
    latest_passed: int
    latest_failed: int
    in_progress: int
    no_run: int
    with_accepted: int


@dataclass(frozen=True, slots=True)
class FleetPage:
    rows: list[FleetRow]
    totals: FleetTotals


def fleet(session: Session, *, limit: int, after_id: str | None) -> FleetPage:
    """Up to `limit` robots by id after `after_id`, each with its latest run and accepted
    calibration, and the fleet's totals: one statement, whatever the number of robots.

    The newest run and the newest passed result of each robot are correlated subqueries on
    `ix_runs_robot_created` and `ix_results_robot_passed`: one index probe per robot, where a
    window over every run would sort the whole table.
    """
    latest = _latest_per_robot()
    totals = _fleet_totals(latest)
    page_stmt = select(latest).order_by(latest.c.robot_id).limit(limit)
    if after_id is not None:
        page_stmt = page_stmt.where(latest.c.robot_id > after_id)
    page = page_stmt.cte("page")
    accepted = aliased(Result, name="accepted")
    stmt = (
        select(
            *totals.c,
            *page.c,
            accepted.measured_at.label("accepted_measured_at"),
            accepted.metric_error_final.label("accepted_metric_error_final"),
        )
        # The totals row is there even when the page is empty (a cursor past the last robot).
        .select_from(totals)
        .outerjoin(page, true())
        .outerjoin(accepted, accepted.run_id == page.c.accepted_run_id)
        .order_by(page.c.robot_id)
    )
    rows = session.connection().execute(stmt).mappings().all()
    totals_row = FleetTotals(**{column.name: int(rows[0][column.name]) for column in totals.c})
    return FleetPage(
        rows=[_fleet_row(row) for row in rows if row["robot_id"] is not None], totals=totals_row
    )


def _latest_per_robot() -> Any:
    """The CTE `latest`: every robot's columns, its newest run with that run's verdict, and the
    id of its newest accepted result's run."""
    newest_run = aliased(Run, name="newest_run")
    newest_passed = aliased(Result, name="newest_passed")
    latest_run_id = (
        select(newest_run.id)
        .where(newest_run.robot_id == Robot.id)
        .order_by(newest_run.created_at.desc(), newest_run.id.desc())
        .limit(1)
        .scalar_subquery()
    )
    accepted_run_id = (
        select(newest_passed.run_id)
        .where(newest_passed.robot_id == Robot.id, newest_passed.accepted.is_(True))
        .order_by(newest_passed.measured_at.desc(), newest_passed.run_id.desc())
        .limit(1)
        .scalar_subquery()
    )
    return (
        select(
            Robot.id.label("robot_id"),
            Robot.model,
            Robot.meta.label("robot_metadata"),
            Robot.created_at.label("robot_created_at"),
            Robot.updated_at.label("robot_updated_at"),
            *(column.label(f"run_{column.key}") for column in _RUN_COLUMNS),
            Result.passed,
            Result.metric_error_final,
            accepted_run_id.label("accepted_run_id"),
        )
        .select_from(Robot)
        .outerjoin(Run, Run.id == latest_run_id)
        .outerjoin(Result, Result.run_id == Run.id)
        .cte("latest")
    )


def _fleet_totals(latest: Any) -> Any:
    """The CTE `totals`: `FleetTotals`' counts over `latest` (every robot, not one page)."""
    status, passed = latest.c.run_status, latest.c.passed

    def count_of(condition: Any) -> Any:
        return func.coalesce(func.sum(case((condition, 1), else_=0)), 0)

    return select(
        func.count().label("robots"),
        count_of((status == RunStatus.SUCCEEDED) & passed.is_(True)).label("latest_passed"),
        count_of((status == RunStatus.FAILED) | passed.is_(False)).label("latest_failed"),
        count_of(status.in_([RunStatus.QUEUED, RunStatus.RUNNING])).label("in_progress"),
        count_of(latest.c.run_id.is_(None)).label("no_run"),
        count_of(latest.c.accepted_run_id.is_not(None)).label("with_accepted"),
    ).cte("totals")


def _fleet_row(row: Any) -> FleetRow:
    run = RunColumns(*(row[f"run_{column.key}"] for column in _RUN_COLUMNS))
    return FleetRow(
        robot=RobotColumns(
            row["robot_id"],
            row["model"],
            row["robot_metadata"],
            row["robot_created_at"],
            row["robot_updated_at"],
        ),
        latest=None if run.id is None else RunRow(run, row["passed"], row["metric_error_final"]),
        accepted=None
        if row["accepted_run_id"] is None
        else AcceptedRow(
            row["accepted_run_id"], row["accepted_measured_at"], row["accepted_metric_error_final"]
        ),
    )


# -- tolerance profiles ---------------------------------------------------------------------------


def get_tolerance_profile(session: Session, name: str) -> ToleranceProfile | None:
    return session.get(ToleranceProfile, name)


def list_tolerance_profiles(session: Session) -> list[ToleranceProfile]:
    return list(session.scalars(select(ToleranceProfile).order_by(ToleranceProfile.name)))


def put_tolerance_profile(
    session: Session,
    name: str,
    *,
    robot_model: str | None,
    is_default: bool,
    limits: dict[str, Any],
    design_extrinsics: dict[str, Any] | None,
) -> tuple[ToleranceProfile, bool]:
    """Create or replace a profile; returns (profile, created). Making it the default clears
    the flag elsewhere in the same transaction, so there is at most one default."""
    if is_default:
        session.execute(
            update(ToleranceProfile)
            .where(ToleranceProfile.is_default.is_(True), ToleranceProfile.name != name)
            .values(is_default=False, updated_at=datetime.now(UTC))
        )
    profile = session.get(ToleranceProfile, name)
    created = profile is None
    if profile is None:
        profile = ToleranceProfile(name=name)
        session.add(profile)
    profile.robot_model = robot_model
    profile.is_default = is_default
    profile.limits = limits
    profile.design_extrinsics = design_extrinsics
    session.flush()
    return profile, created


def tolerance_profile_for_model(session: Session, robot_model: str) -> ToleranceProfile | None:
    return session.scalar(
        select(ToleranceProfile).where(ToleranceProfile.robot_model == robot_model)
    )


def tolerance_profile_for(session: Session, robot: Robot) -> ToleranceProfile | None:
    """The profile for the robot's model, else the default profile, else None."""
    if robot.model is not None:
        profile = tolerance_profile_for_model(session, robot.model)
        if profile is not None:
            return profile
    return session.scalar(select(ToleranceProfile).where(ToleranceProfile.is_default.is_(True)))


def count_runs_by_status(session: Session) -> dict[RunStatus, int]:
    counts = dict.fromkeys(RunStatus, 0)
    for status, count in session.execute(select(Run.status, func.count()).group_by(Run.status)):
        counts[status] = count
    return counts


def oldest_queued_at(session: Session) -> datetime | None:
    return session.scalar(
        select(Run.available_at)
        .where(Run.status == RunStatus.QUEUED)
        .order_by(Run.available_at)
        .limit(1)
    )


@dataclass(frozen=True, slots=True)
class FleetCalibrationRow:
    """One LiDAR of a robot's calibration in use (or the robot alone, `point` None, if none)."""

    robot_id: str
    model: str | None
    metric_error_final: float | None
    point: ExtrinsicPoint | None


def fleet_calibrations(session: Session) -> list[FleetCalibrationRow]:
    """Every robot by id with the extrinsics of its newest accepted result, frame by frame."""
    newest = aliased(Result, name="newest_accepted")
    accepted_run_id = (
        select(newest.run_id)
        .where(newest.robot_id == Robot.id, newest.accepted.is_(True))
        .order_by(newest.measured_at.desc(), newest.run_id.desc())
        .limit(1)
        .scalar_subquery()
    )
    stmt = (
        select(Robot.id, Robot.model, Result.metric_error_final, *_POINT_COLUMNS)
        .select_from(Robot)
        .outerjoin(Result, Result.run_id == accepted_run_id)
        .outerjoin(LidarExtrinsic, LidarExtrinsic.run_id == Result.run_id)
        .order_by(Robot.id, LidarExtrinsic.frame)
    )
    rows = []
    for robot_id, model, final, *point in session.connection().execute(stmt).all():
        extrinsic = None if point[0] is None else _point(point)
        rows.append(FleetCalibrationRow(robot_id, model, final, extrinsic))
    return rows
