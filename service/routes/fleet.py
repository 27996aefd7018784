"""The fleet at a glance: each robot with its latest run and its latest accepted calibration, one
page per request, and totals over the whole fleet (the dashboard's overview). One SQL statement
per request, whatever the fleet's size (`repository.fleet`)."""

from __future__ import annotations

import uuid
from dataclasses import asdict
from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import BaseModel, Field

from service import repository
from service.deps import ReadKey, SessionDep
from service.pagination import (
    PAGE_SIZE_DEFAULT,
    PAGE_SIZE_MAX,
    cursor_robot_id,
    decode_cursor,
    encode_cursor,
)
from service.problem_details import PROBLEM_RESPONSES
from service.routes.runs import run_summary
from service.schemas import RobotPublic, RunSummary

router = APIRouter(prefix="/v1/fleet", tags=["robots"], responses=PROBLEM_RESPONSES)


class AcceptedCalibration(BaseModel):
    run_id: uuid.UUID
    measured_at: datetime = Field(description="When its recording was uploaded.")
    metric_error_final: float | None


class FleetRobot(RobotPublic):
    latest_run: RunSummary | None
    latest_calibration: AcceptedCalibration | None = Field(
        description="The newest accepted run (passed, or accepted by an operator, and not "
        "rejected): the calibration the robot should be using."
    )


class FleetTotals(BaseModel):
    """Counts over every robot of the fleet (not only this page), by each robot's latest run."""

    robots: int
    latest_passed: int = Field(description="Robots whose latest run passed its verdict.")
    latest_failed: int = Field(
        description="Robots whose latest run failed: its verdict, or the run itself."
    )
    in_progress: int = Field(description="Robots whose latest run is queued or running.")
    no_run: int = Field(description="Robots that never uploaded a recording.")
    with_accepted: int = Field(description="Robots with an accepted calibration.")


class FleetPage(BaseModel):
    items: list[FleetRobot]
    next_cursor: str | None
    totals: FleetTotals


@router.get("", summary="Robots with their latest run and accepted calibration, by id")
def get_fleet(
    _: ReadKey,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=PAGE_SIZE_MAX)] = PAGE_SIZE_DEFAULT,
    cursor: Annotated[str | None, Query(max_length=512)] = None,
) -> FleetPage:
    # The cursor of `/v1/robots`: both list robots by id.
    after = decode_cursor(cursor, "robots", cursor_robot_id)[0] if cursor is not None else None
    page = repository.fleet(session, limit=limit + 1, after_id=after)
    rows = page.rows[:limit]
    next_cursor = encode_cursor("robots", rows[-1].robot.id) if len(page.rows) > limit else None
    return FleetPage(
        items=[_fleet_robot(row) for row in rows],
        next_cursor=next_cursor,
        totals=FleetTotals(**asdict(page.totals)),
    )


def _fleet_robot(row: repository.FleetRow) -> FleetRobot:
    latest, accepted = row.latest, row.accepted
    return FleetRobot(
        id=row.robot.id,
        model=row.robot.model,
        metadata=row.robot.metadata,
        created_at=row.robot.created_at,
        updated_at=row.robot.updated_at,
        latest_run=run_summary(latest.run, latest.passed, latest.metric_error_final)
        if latest
        else None,
        latest_calibration=AcceptedCalibration(
            run_id=accepted.run_id,
            measured_at=accepted.measured_at,
            metric_error_final=accepted.metric_error_final,
        )
        if accepted
        else None,
    )
