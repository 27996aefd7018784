"""Compare two runs of a robot: per LiDAR, how far its `T_base_lidar` moved and turned between
them, with both verdicts (what a maintenance engineer asks after a mount was touched)."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Query
from sqlalchemy.orm import Session

from pipeline import from_translation_xyzw, pose_difference
from service import repository
from service.deps import CurrentKey, RobotIdPath, SessionDep
from service.models import Result
from service.problem_details import PROBLEM_RESPONSES, Forbidden, RunNotFound
from service.routes.exports import RunHasNoResultError
from service.schemas import ComparedRun, LidarChange, RunComparison

router = APIRouter(prefix="/v1/robots", tags=["robots"], responses=PROBLEM_RESPONSES)


@router.get("/{robot_id}/compare", summary="How each LiDAR changed between two runs of a robot")
def compare_runs(
    robot_id: RobotIdPath,
    principal: CurrentKey,
    session: SessionDep,
    from_run: Annotated[uuid.UUID, Query(alias="from", description="The earlier (first) run.")],
    to_run: Annotated[uuid.UUID, Query(alias="to", description="The later (second) run.")],
) -> RunComparison:
    if not principal.may_read_robot(robot_id):
        raise Forbidden(f"this key may not read robot {robot_id!r}")
    first, second = _result(session, robot_id, from_run), _result(session, robot_id, to_run)
    before = {p.frame: p for p in repository.extrinsics_of(session, from_run)}
    after = {p.frame: p for p in repository.extrinsics_of(session, to_run)}
    lidars = {}
    for frame in sorted(before.keys() | after.keys() | _frames(first) | _frames(second)):
        a, b = before.get(frame), after.get(frame)
        if a is None or b is None:
            lidars[frame] = LidarChange(
                translation_m=None,
                rotation_deg=None,
                delta_translation=None,
                in_from=a is not None,
                in_to=b is not None,
            )
            continue
        distance_m, angle_deg = pose_difference(
            from_translation_xyzw(a.translation, a.rotation_xyzw),
            from_translation_xyzw(b.translation, b.rotation_xyzw),
        )
        dx, dy, dz = (tb - ta for ta, tb in zip(a.translation, b.translation, strict=True))
        lidars[frame] = LidarChange(
            translation_m=distance_m,
            rotation_deg=angle_deg,
            delta_translation=(dx, dy, dz),
            in_from=True,
            in_to=True,
        )
    return RunComparison(
        robot_id=robot_id, from_run=_side(first), to_run=_side(second), lidars=lidars
    )


def _result(session: Session, robot_id: str, run_id: uuid.UUID) -> Result:
    found = repository.get_run(session, run_id)
    if found is None or found[0].robot_id != robot_id:
        raise RunNotFound(f"robot {robot_id!r} has no run {run_id}")
    run, result = found
    if result is None:
        raise RunHasNoResultError(
            f"run {run_id} has no result to compare (it is {run.status.value})"
        )
    return result


def _frames(result: Result) -> set[str]:
    """Every LiDAR of the result, those the data could not determine included."""
    return set(result.document.get("lidars", {}))


def _side(result: Result) -> ComparedRun:
    return ComparedRun(
        run_id=result.run_id,
        measured_at=result.measured_at,
        passed=result.passed,
        accepted=result.accepted,
    )
