"""CSV exports for spreadsheets and fleet tools: a robot's per-LiDAR history, and the fleet's
calibrations in use. One row per LiDAR and run; `T_base_lidar` as translation (m) and quaternion."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from typing import Annotated, Any

from fastapi import APIRouter, Query
from fastapi.responses import Response

from service import repository
from service.deps import CurrentKey, ReadKey, RobotIdPath, SessionDep
from service.parameters import FrameQuery, SinceQuery, UntilQuery
from service.problem_details import PROBLEM_RESPONSES, Forbidden, RobotNotFound

router = APIRouter(tags=["exports"], responses=PROBLEM_RESPONSES)

POSE_COLUMNS = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")
HISTORY_COLUMNS = (
    "robot_id",
    "run_id",
    "measured_at",
    "frame",
    "is_reference",
    "passed",
    "accepted",
    *POSE_COLUMNS,
)
FLEET_COLUMNS = (
    "robot_id",
    "model",
    "run_id",
    "measured_at",
    "metric_error_final",
    "frame",
    "is_reference",
    *POSE_COLUMNS,
)
_PAGE = 1000
_CSV: dict[int | str, dict[str, Any]] = {
    200: {"description": "CSV with a header row.", "content": {"text/csv": {}}}
}


def _csv(header: Sequence[str], rows: Iterable[Sequence[object]], filename: str) -> Response:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return Response(
        buffer.getvalue(),
        media_type="text/csv; charset=utf-8",
        headers={"Content-Disposition": f'attachment; filename="{filename}"'},
    )


def _point_cells(point: repository.ExtrinsicPoint) -> list[object]:
    return [*(repr(v) for v in point.translation), *(repr(v) for v in point.rotation_xyzw)]


@router.get(
    "/v1/robots/{robot_id}/history.csv",
    summary="A robot's per-LiDAR extrinsic history as CSV, oldest first",
    response_class=Response,
    responses=_CSV,
)
def history_csv(
    robot_id: RobotIdPath,
    principal: CurrentKey,
    session: SessionDep,
    frame: FrameQuery = None,
    accepted: Annotated[
        bool | None, Query(description="true: calibrations in use (accepted) only.")
    ] = None,
    since: SinceQuery = None,
    until: UntilQuery = None,
) -> Response:
    if not principal.may_read_robot(robot_id):
        raise Forbidden(f"this key may not read robot {robot_id!r}")
    if repository.get_robot(session, robot_id) is None:
        raise RobotNotFound(f"no robot {robot_id!r}")
    rows: list[list[object]] = []
    after = None
    while True:
        page = repository.history(
            session,
            robot_id,
            frame=frame,
            passed=None,
            accepted=accepted,
            since=since,
            until=until,
            limit=_PAGE,
            after=after,
        )
        rows += [
            [
                robot_id,
                p.run_id,
                p.measured_at.isoformat(),
                p.frame,
                p.is_reference,
                p.passed,
                p.accepted,
                *_point_cells(p),
            ]
            for p in page
        ]
        if len(page) < _PAGE:
            break
        after = (page[-1].measured_at, page[-1].id)
    return _csv(HISTORY_COLUMNS, rows, f"{robot_id}-history.csv")


@router.get(
    "/v1/fleet/calibrations.csv",
    summary="Every robot's calibration in use as CSV (a robot without one: one row, no pose)",
    response_class=Response,
    responses=_CSV,
)
def fleet_calibrations_csv(_: ReadKey, session: SessionDep) -> Response:
    rows = [
        [row.robot_id, row.model or "", "", "", "", "", "", *([""] * len(POSE_COLUMNS))]
        if row.point is None
        else [
            row.robot_id,
            row.model or "",
            row.point.run_id,
            row.point.measured_at.isoformat(),
            "" if row.metric_error_final is None else repr(row.metric_error_final),
            row.point.frame,
            row.point.is_reference,
            *_point_cells(row.point),
        ]
        for row in repository.fleet_calibrations(session)
    ]
    return _csv(FLEET_COLUMNS, rows, "fleet-calibrations.csv")
