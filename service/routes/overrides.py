"""Overrides: an operator accepts a failed calibration or rejects a passed one, with a reason.
The calibration in use (`GET /v1/robots/{robot_id}/calibration`, drift references, the fleet)
follows it; the run lists its overrides (who, when, why)."""

from __future__ import annotations

import uuid

from fastapi import APIRouter
from sqlalchemy.orm import Session

from service import overrides, repository
from service.deps import OverrideKey, WriteSessionDep
from service.models import OverrideAction
from service.problem_details import PROBLEM_RESPONSES, OverrideConflict, RunNotFound
from service.routes.exports import RunHasNoResultError
from service.routes.runs import run_public
from service.schemas import OverrideIn, RunPublic

router = APIRouter(prefix="/v1/runs", tags=["overrides"], responses=PROBLEM_RESPONSES)


@router.post(
    "/{run_id}/accept",
    summary="Accept the run's calibration despite its verdict (override scope)",
)
def accept_run(
    run_id: uuid.UUID, body: OverrideIn, principal: OverrideKey, session: WriteSessionDep
) -> RunPublic:
    return _override(session, run_id, OverrideAction.ACCEPT, body.reason, principal.key_id)


@router.post(
    "/{run_id}/reject",
    summary="Reject the run's calibration: the robot uses its previous one (override scope)",
)
def reject_run(
    run_id: uuid.UUID, body: OverrideIn, principal: OverrideKey, session: WriteSessionDep
) -> RunPublic:
    return _override(session, run_id, OverrideAction.REJECT, body.reason, principal.key_id)


def _override(
    session: Session,
    run_id: uuid.UUID,
    action: OverrideAction,
    reason: str,
    key_id: str,
) -> RunPublic:
    found = repository.get_run(session, run_id)
    if found is None:
        raise RunNotFound(f"no run {run_id}")
    if found[1] is None:
        raise RunHasNoResultError(
            f"run {run_id} has no result to {action.value} (it is {found[0].status.value})"
        )
    try:
        overrides.override(session, run_id, action, reason=reason, key_id=key_id)
    except repository.OverrideConflictError as err:
        raise OverrideConflict(str(err)) from err
    session.commit()
    found = repository.get_run(session, run_id)
    assert found is not None
    run, result = found
    return run_public(run, result, overrides.overrides_of(session, [run_id])[run_id])
