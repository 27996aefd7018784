"""The calling key: what it may do, so that a client (the dashboard) offers only the actions the
key may take instead of offering them all and failing with 403."""

from __future__ import annotations

from fastapi import APIRouter

from service.deps import CurrentKey, SessionDep
from service.models import ApiKey
from service.problem_details import PROBLEM_RESPONSES
from service.schemas import KeyPublic

router = APIRouter(prefix="/v1/keys", tags=["keys"], responses=PROBLEM_RESPONSES)


@router.get("/me", summary="The calling API key: its id, name, scopes and robot (any key)")
def current_key(principal: CurrentKey, session: SessionDep) -> KeyPublic:
    row = session.get(ApiKey, principal.key_id)
    return KeyPublic(
        id=principal.key_id,
        name=row.name if row is not None else None,
        scopes=sorted(principal.scopes),
        robot_id=principal.robot_id,
    )
