"""What a claimed run's verdict is compared with, read from the database: the robot's tolerance
profile, its last accepted calibration (maintenance) or its model's design (end of line)."""

from __future__ import annotations

from datetime import timedelta

from service import overrides, repository
from service.db import Database
from service.models import OverrideAction, RunKind
from tests.service.documents import result_document
from tests.service.routes.accepted import determined
from tests.workers.runs import enqueue, finished_run
from workers import queue
from workers.context import RunContext, load_context

DESIGN = {"lidar_rear": {"translation": [-0.4, 0.0, 0.62], "rotation_xyzw": [0.0, 0.0, 1.0, 0.0]}}
LIMITS = {
    "max_metric_error_m": 0.02,
    "max_translation_drift_m": 0.01,
    "max_rotation_drift_deg": 0.5,
    "max_translation_deviation_m": 0.03,
}


def context_of_next_claim(db: Database) -> RunContext:
    held = queue.claim(db, "w", timedelta(minutes=1))
    assert held is not None
    with db.session() as session:
        return load_context(session, held)


def set_up_profile(db: Database) -> None:
    with db.transaction() as session:
        repository.put_robot(session, "R1", model="m1", metadata={})
        repository.put_tolerance_profile(
            session,
            "m1",
            robot_model="m1",
            is_default=False,
            limits=LIMITS,
            design_extrinsics=DESIGN,
        )


def test_a_maintenance_run_is_compared_with_the_last_accepted_calibration(db: Database) -> None:
    set_up_profile(db)
    older = finished_run(db, result_document(rear_x=-0.40))
    accepted = finished_run(db, result_document(rear_x=-0.41))
    finished_run(db, result_document(passed=False, rear_x=-0.60))  # not accepted: ignored
    enqueue(db, kind=RunKind.MAINTENANCE)
    context = context_of_next_claim(db)
    assert context.profile == "m1" and context.limits == LIMITS
    reference = context.reference
    assert reference is not None and reference.against == "last_accepted"
    assert reference.run_id == str(accepted) != str(older)
    assert reference.poses["lidar_rear"][0][0] == -0.41
    assert set(reference.poses) == {"lidar_front", "lidar_rear"}, "undetermined LiDARs have none"
    assert (reference.max_translation_m, reference.max_rotation_deg) == (0.01, 0.5)


def test_an_end_of_line_run_is_compared_with_the_design(db: Database) -> None:
    set_up_profile(db)
    finished_run(db, result_document())
    enqueue(db, kind=RunKind.END_OF_LINE)
    reference = context_of_next_claim(db).reference
    assert reference is not None and reference.against == "design"
    assert reference.poses == {"lidar_rear": ((-0.4, 0.0, 0.62), (0.0, 0.0, 1.0, 0.0))}
    assert (reference.max_translation_m, reference.max_rotation_deg) == (0.03, None)


def test_without_profile_or_history_there_is_nothing_to_compare(db: Database) -> None:
    enqueue(db, kind=RunKind.MAINTENANCE)
    context = context_of_next_claim(db)
    assert context.profile is None and context.limits == {} and context.reference is None


def test_the_drift_reference_follows_operators_overrides(db: Database) -> None:
    set_up_profile(db)
    older = finished_run(db, determined(), kind=RunKind.MAINTENANCE)
    newer = finished_run(db, determined(), kind=RunKind.MAINTENANCE)
    failed = finished_run(db, determined(passed=False), kind=RunKind.MAINTENANCE)
    with db.transaction() as session:
        overrides.override(session, newer, OverrideAction.REJECT, reason="door open", key_id="k")
    enqueue(db, kind=RunKind.MAINTENANCE)
    reference = context_of_next_claim(db).reference
    assert reference is not None and reference.run_id == str(older), "the rejected one is skipped"
    with db.transaction() as session:
        overrides.override(session, failed, OverrideAction.ACCEPT, reason="checked", key_id="k")
    enqueue(db, kind=RunKind.MAINTENANCE)
    reference = context_of_next_claim(db).reference
    assert reference is not None and reference.run_id == str(failed), "accepted: in use"
