"""Operators' overrides of a verdict: accept a failed calibration or reject a passed one, with a
reason. Each is an `Override` row (who, when, why) written in the transaction that flips the
result's and its extrinsics' `accepted` flag, which every "calibration in use" query follows.
"""

from __future__ import annotations

import uuid
from datetime import UTC, datetime

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from service.models import ApiKey, LidarExtrinsic, Override, OverrideAction, Result
from service.repository import OverrideConflictError, UnknownRunError


def override(
    session: Session,
    run_id: uuid.UUID,
    action: OverrideAction,
    *,
    reason: str,
    key_id: str,
) -> Override:
    """Accept or reject the run's result. Raises `UnknownRunError` if the run has no result,
    `OverrideConflictError` if the result already is what `action` asks for, or is a result an
    operator may not accept (a LiDAR the data could not determine has no pose to use)."""
    result = session.get(Result, run_id, with_for_update=True, populate_existing=True)
    if result is None:
        raise UnknownRunError(f"run {run_id} has no result")
    accept = action is OverrideAction.ACCEPT
    if result.accepted == accept:
        state = "accepted" if accept else "rejected"
        raise OverrideConflictError(
            f"run {run_id}'s calibration is already {state}; nothing to {action.value}"
        )
    if accept:
        undetermined = sorted(
            frame
            for frame, lidar in result.document.get("lidars", {}).items()
            if lidar.get("calibrated") is None
        )
        if undetermined:
            raise OverrideConflictError(
                f"run {run_id} could not determine {', '.join(undetermined)}: there is no "
                "calibration to accept; record the routine again"
            )
    result.accepted = accept
    session.execute(
        update(LidarExtrinsic)
        .where(LidarExtrinsic.run_id == run_id)
        .values(accepted=accept)
        .execution_options(synchronize_session=False)
    )
    row = Override(
        run_id=run_id,
        robot_id=result.robot_id,
        action=action,
        reason=reason,
        key_id=key_id,
        # The key's name, as it was: a key renamed or revoked later keeps the audit readable.
        key_name=key.name if (key := session.get(ApiKey, key_id)) is not None else None,
        created_at=datetime.now(UTC),
    )
    session.add(row)
    session.flush()
    return row


def overrides_of(session: Session, run_ids: list[uuid.UUID]) -> dict[uuid.UUID, list[Override]]:
    """The overrides of each run, oldest first (the audit trail)."""
    found: dict[uuid.UUID, list[Override]] = {run_id: [] for run_id in run_ids}
    if not run_ids:
        return found
    rows = session.scalars(
        select(Override)
        .where(Override.run_id.in_(run_ids))
        .order_by(Override.created_at, Override.id)
    )
    for row in rows:
        found[row.run_id].append(row)
    return found
