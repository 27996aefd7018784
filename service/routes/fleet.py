"""The fleet at a glance: each robot with its latest run and its latest accepted calibration, one
page per request (the dashboard's overview)."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, Query
from pydantic import BaseModel, Field

from service import repository
from service.deps import ReadKey, SessionDep
from service.pagination import PAGE_SIZE_DEFAULT, PAGE_SIZE_MAX
from service.problems import PROBLEM_RESPONSES
from service.routes.robots import robot_public, robots_page
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
        description="The newest run that passed: the calibration the robot should be using."
    )


class FleetPage(BaseModel):
    items: list[FleetRobot]
    next_cursor: str | None


@router.get("", summary="Robots with their latest run and accepted calibration, by id")
def get_fleet(
    _: ReadKey,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=PAGE_SIZE_MAX)] = PAGE_SIZE_DEFAULT,
    cursor: Annotated[str | None, Query(max_length=512)] = None,
) -> FleetPage:
    robots, next_cursor = robots_page(session, limit, cursor)
    items = []
    for robot in robots:
        latest = repository.latest_run(session, robot.id)
        accepted = repository.latest_calibration(session, robot.id)
        items.append(
            FleetRobot(
                **robot_public(robot).model_dump(),
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
        )
    return FleetPage(items=items, next_cursor=next_cursor)
