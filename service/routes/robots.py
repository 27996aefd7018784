"""Robots: the fleet list, one robot, its latest accepted calibration and its extrinsic history."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Response
from pydantic import TypeAdapter
from sqlalchemy.orm import Session

from pipeline import ResultDocument
from service import repository
from service.auth import Principal
from service.deps import AdminKey, CurrentKey, ReadKey, RobotIdPath, SessionDep, WriteSessionDep
from service.models import Robot
from service.pagination import (
    PAGE_SIZE_DEFAULT,
    PAGE_SIZE_MAX,
    cursor_datetime,
    cursor_robot_id,
    cursor_row_id,
    decode_cursor,
    encode_cursor,
)
from service.parameters import CursorQuery, FrameQuery, SinceQuery, UntilQuery
from service.problem_details import (
    PROBLEM_RESPONSES,
    Forbidden,
    NoCalibration,
    RobotNotFound,
)
from service.routes.runs import run_summary
from service.schemas import (
    CalibrationPublic,
    HistoryPage,
    HistoryPoint,
    LidarCalibration,
    RobotDetail,
    RobotPage,
    RobotPublic,
    RobotUpdate,
)

router = APIRouter(prefix="/v1/robots", tags=["robots"], responses=PROBLEM_RESPONSES)

_HISTORY_POINTS = TypeAdapter(list[HistoryPoint])
HISTORY_LIMIT_DEFAULT = 1000
HISTORY_LIMIT_MAX = 10_000


@router.get("", summary="Robots, by id, cursor-paginated")
def list_robots(
    _: ReadKey,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=PAGE_SIZE_MAX)] = PAGE_SIZE_DEFAULT,
    cursor: CursorQuery = None,
) -> RobotPage:
    robots, next_cursor = robots_page(session, limit, cursor)
    return RobotPage(items=[robot_public(r) for r in robots], next_cursor=next_cursor)


@router.get("/{robot_id}", summary="A robot, its tolerance profile and latest run")
def get_robot(robot_id: RobotIdPath, principal: CurrentKey, session: SessionDep) -> RobotDetail:
    robot = _readable_robot(session, principal, robot_id)
    profile = repository.tolerance_profile_for(session, robot)
    latest = repository.latest_run(session, robot_id)
    return RobotDetail(
        **robot_public(robot).model_dump(),
        tolerance_profile=profile.name if profile else None,
        latest_run=run_summary(
            latest.run, latest.passed, latest.metric_error_final, latest.accepted
        )
        if latest
        else None,
    )


@router.put(
    "/{robot_id}",
    summary="Register a robot or set its model and metadata (admin)",
    responses={201: {"description": "Created."}},
)
def put_robot(
    robot_id: RobotIdPath,
    body: RobotUpdate,
    _: AdminKey,
    session: WriteSessionDep,
    response: Response,
) -> RobotPublic:
    robot, created = repository.put_robot(
        session, robot_id, model=body.model, metadata=body.metadata
    )
    session.commit()
    response.status_code = 201 if created else 200
    return robot_public(robot)


@router.get("/{robot_id}/calibration", summary="The robot's latest accepted calibration")
def get_calibration(
    robot_id: RobotIdPath, principal: CurrentKey, session: SessionDep
) -> CalibrationPublic:
    _check_readable(principal, robot_id)
    result = repository.latest_calibration(session, robot_id)
    if result is None:
        _readable_robot(session, principal, robot_id)  # 404 if there is no such robot
        raise NoCalibration(f"robot {robot_id!r} has no passed calibration yet")
    lidars = {
        point.frame: LidarCalibration(
            translation=point.translation,
            rotation_xyzw=point.rotation_xyzw,
            is_reference=point.is_reference,
            stddev=point.stddev,
        )
        for point in repository.extrinsics_of(session, result.run_id)
    }
    return CalibrationPublic(
        robot_id=robot_id,
        run_id=result.run_id,
        measured_at=result.measured_at,
        metric_error_initial=result.metric_error_initial,
        metric_error_final=result.metric_error_final,
        pipeline_version=result.pipeline_version,
        lidars=lidars,
        result=ResultDocument.model_validate(result.document),
    )


@router.get("/{robot_id}/history", summary="Per-LiDAR extrinsics over time, oldest first")
def get_history(
    robot_id: RobotIdPath,
    principal: CurrentKey,
    session: SessionDep,
    frame: FrameQuery = None,
    passed: Annotated[bool | None, Query(description="true: passed verdicts only.")] = None,
    since: SinceQuery = None,
    until: UntilQuery = None,
    limit: Annotated[int, Query(ge=1, le=HISTORY_LIMIT_MAX)] = HISTORY_LIMIT_DEFAULT,
    cursor: CursorQuery = None,
    accepted: Annotated[
        bool | None,
        Query(description="true: calibrations in use only (verdicts as operators overrode them)."),
    ] = None,
) -> HistoryPage:
    _check_readable(principal, robot_id)
    after = None
    if cursor is not None:
        measured, row_id = decode_cursor(cursor, "history", cursor_datetime, cursor_row_id)
        after = (measured, row_id)
    rows = repository.history(
        session,
        robot_id,
        frame=frame,
        passed=passed,
        accepted=accepted,
        since=since,
        until=until,
        limit=limit + 1,
        after=after,
    )
    if not rows:
        _readable_robot(session, principal, robot_id)  # 404 if there is no such robot
    # One validation call for the page, reading the points' attributes (the hot listing).
    items = _HISTORY_POINTS.validate_python(rows[:limit], from_attributes=True)
    next_cursor = None
    if len(rows) > limit:
        last = rows[limit - 1]
        next_cursor = encode_cursor("history", last.measured_at, last.id)
    return HistoryPage(robot_id=robot_id, items=items, next_cursor=next_cursor)


def robots_page(session: Session, limit: int, cursor: str | None) -> tuple[list[Robot], str | None]:
    """Up to `limit` robots by id after `cursor`, and the cursor of the next page (None: last)."""
    after = decode_cursor(cursor, "robots", cursor_robot_id)[0] if cursor is not None else None
    robots = repository.list_robots(session, limit=limit + 1, after_id=after)
    next_cursor = encode_cursor("robots", robots[limit - 1].id) if len(robots) > limit else None
    return robots[:limit], next_cursor


def robot_public(robot: Robot) -> RobotPublic:
    return RobotPublic(
        id=robot.id,
        model=robot.model,
        metadata=robot.meta,
        created_at=robot.created_at,
        updated_at=robot.updated_at,
    )


def _check_readable(principal: Principal, robot_id: str) -> None:
    if not principal.may_read_robot(robot_id):
        raise Forbidden(f"this key may not read robot {robot_id!r}")


def _readable_robot(session: Session, principal: Principal, robot_id: str) -> Robot:
    """The robot, if the key may read it (403) and it exists (404). Listings skip the lookup
    when they find rows: rows imply the robot."""
    _check_readable(principal, robot_id)
    robot = repository.get_robot(session, robot_id)
    if robot is None:
        raise RobotNotFound(f"no robot {robot_id!r}")
    return robot
