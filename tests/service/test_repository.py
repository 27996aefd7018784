"""The data layer the worker uses: `store_result` and `fail_run` write a run's outcome in one
transaction; tolerance profiles resolve per robot model; runs record and list as the API needs."""

from __future__ import annotations

import math
import threading
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime

import jsonschema
import pytest
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError

from pipeline.result_model import result_schema
from service import repository
from service.db import Database
from service.models import LidarExtrinsic, Result, Robot, Run, RunKind, RunStatus
from service.problem_details import problem_document
from service.settings import Settings
from tests.service.documents import result_document
from tests.service.uploads import new_upload


@pytest.fixture
def db(settings: Settings) -> Iterator[Database]:
    database = Database.from_settings(settings)
    yield database
    database.dispose()


def queued_run(
    db: Database,
    robot_id: str = "R1",
    *,
    idempotency_key: str | None = None,
    create_robot: bool = True,
) -> uuid.UUID:
    run_id = uuid.uuid4()
    upload = new_upload(
        robot_id,
        run_id=run_id,
        kind=RunKind.MAINTENANCE,
        size=10,
        idempotency_key=idempotency_key,
    )
    with db.transaction() as session:
        repository.record_upload(session, upload, create_robot=create_robot)
    return run_id


def claim(db: Database, run_id: uuid.UUID, owner: str) -> None:
    """What the worker's claim does to the row (the queue itself is the workers' module)."""
    with db.transaction() as session:
        run = session.get(Run, run_id)
        assert run is not None
        run.status, run.lease_owner, run.attempts = RunStatus.RUNNING, owner, run.attempts + 1
        run.started_at = datetime.now(UTC)


def test_record_upload_queues_the_run_and_creates_the_robot(db: Database) -> None:
    run_id = queued_run(db)
    with db.session() as session:
        run = session.get(Run, run_id)
        assert run is not None and run.status == RunStatus.QUEUED
        assert run.attempts == 0 and run.max_attempts == 3
        assert run.available_at == run.created_at
        assert session.get(Robot, "R1") is not None


def test_two_first_uploads_of_a_new_robot_both_succeed(db: Database) -> None:
    # The first transaction has inserted the robot but not committed when the second starts;
    # the second waits on it (PostgreSQL row lock, SQLite write lock) and must not fail.
    first = db.write_session()
    first.begin()
    repository.record_upload(first, new_upload("R5"), create_robot=True)
    outcome: list[object] = []
    second = threading.Thread(target=lambda: outcome.append(_record_or_error(db, "R5")))
    second.start()
    second.join(0.5)
    first.commit()
    first.close()
    second.join(10)
    assert outcome == ["ok"]
    with db.session() as session:
        assert session.scalar(select(func.count()).select_from(Run)) == 2
        assert session.scalar(select(func.count()).select_from(Robot)) == 1


def _record_or_error(db: Database, robot_id: str) -> object:
    try:
        with db.transaction() as session:
            repository.record_upload(session, new_upload(robot_id), create_robot=True)
    except Exception as err:  # the test reports what went wrong instead of hanging
        return err
    return "ok"


def test_record_upload_without_robot_creation_refuses_unknown_robots(db: Database) -> None:
    with pytest.raises(repository.UnknownRobotError):
        queued_run(db, "ghost", create_robot=False)
    with db.session() as session:
        assert session.scalar(select(func.count()).select_from(Run)) == 0


def test_an_idempotency_key_is_unique_per_robot(db: Database) -> None:
    queued_run(db, "R1", idempotency_key="k1")
    queued_run(db, "R2", idempotency_key="k1")  # another robot may use the same key
    with pytest.raises(IntegrityError):
        queued_run(db, "R1", idempotency_key="k1")


def test_store_result_writes_result_extrinsics_and_status_together(db: Database) -> None:
    run_id = queued_run(db)
    claim(db, run_id, "worker-1")
    document = result_document()
    with db.transaction() as session:
        repository.store_result(session, run_id, document, lease_owner="worker-1")

    with db.session() as session:
        run = session.get(Run, run_id)
        result = session.get(Result, run_id)
        rows = repository.extrinsics_of(session, run_id)
    assert run is not None and result is not None
    assert run.status == RunStatus.SUCCEEDED and run.finished_at is not None
    assert run.lease_owner is None and run.lease_expires_at is None and run.progress == 1.0
    assert result.document == document
    assert result.passed is True
    assert (result.metric_error_initial, result.metric_error_final) == (0.021, 0.0012)
    assert result.pipeline_version == "0.1.0" and result.config_hash == document["config_hash"]
    assert result.measured_at == run.created_at and result.robot_id == "R1"
    # The undetermined LiDAR stays in the document but gets no extrinsics row.
    assert [row.frame for row in rows] == ["lidar_front", "lidar_rear"]
    front, rear = rows
    assert front.is_reference and not rear.is_reference
    assert rear.translation == (-0.41, 0.004, 0.618)
    assert rear.rotation_xyzw == (0.0012, -0.0008, 0.9999985, 0.0009)
    assert rear.stddev == document["lidars"]["lidar_rear"]["stddev"]
    assert all(row.passed and row.measured_at == run.created_at for row in rows)


def test_the_test_document_follows_the_result_schema() -> None:
    jsonschema.Draft202012Validator(result_schema()).validate(result_document())


def test_store_result_twice_keeps_the_first(db: Database) -> None:
    run_id = queued_run(db)
    with db.transaction() as session:
        repository.store_result(session, run_id, result_document(final=0.001))
    with pytest.raises(repository.RunFinishedError), db.transaction() as session:
        repository.store_result(session, run_id, result_document(final=0.002))
    with db.session() as session:
        assert session.scalar(select(func.count()).select_from(Result)) == 1
        assert session.scalar(select(func.count()).select_from(LidarExtrinsic)) == 2
        result = session.get(Result, run_id)
        assert result is not None and result.metric_error_final == 0.001


def test_store_result_refuses_a_worker_that_lost_its_lease(db: Database) -> None:
    run_id = queued_run(db)
    claim(db, run_id, "worker-2")  # the reaper re-queued it and another worker took it
    with pytest.raises(repository.LeaseLostError), db.transaction() as session:
        repository.store_result(session, run_id, result_document(), lease_owner="worker-1")
    with db.session() as session:
        assert session.get(Result, run_id) is None
        run = session.get(Run, run_id)
        assert run is not None and run.status == RunStatus.RUNNING


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("verdict"), "verdict"),
        (lambda d: d["metric_error"].update(final=math.nan), "NaN|nan|finite"),
        (
            lambda d: d["lidars"]["lidar_rear"]["calibrated"].update(translation=[1, 2]),
            "translation",
        ),
        (lambda d: d.update(lidars={}), "lidars"),
        (lambda d: d["lidars"].pop("lidar_rear") and d["lidars"].pop("lidar_left"), "lidars"),
        (
            lambda d: d["lidars"]["lidar_rear"]["calibrated"].update(rotation_xyzw=[0, 0, 0, 0]),
            "no direction",
        ),
        (lambda d: d["lidars"]["lidar_left"].update(undetermined="x and y"), "undetermined"),
        (lambda d: d["verdict"]["checks"][0].update(passed="maybe"), "passed"),
    ],
    ids=[
        "no-verdict",
        "nan-error",
        "short-translation",
        "no-lidars",
        "one-lidar",
        "no-rotation",
        "undetermined-in-words",
        "check-without-outcome",
    ],
)
def test_store_result_refuses_documents_off_contract(db: Database, mutate, match: str) -> None:  # type: ignore[no-untyped-def]
    run_id = queued_run(db)
    document = result_document()
    mutate(document)
    with pytest.raises(repository.InvalidResultError, match=match), db.transaction() as session:
        repository.store_result(session, run_id, document)
    with db.session() as session:
        run = session.get(Run, run_id)
        assert run is not None and run.status == RunStatus.QUEUED
        assert session.scalar(select(func.count()).select_from(Result)) == 0


def test_store_result_for_an_unknown_run(db: Database) -> None:
    with pytest.raises(repository.UnknownRunError), db.transaction() as session:
        repository.store_result(session, uuid.uuid4(), result_document())


def test_fail_run_records_the_problem(db: Database) -> None:
    run_id = queued_run(db)
    claim(db, run_id, "w")
    problem = problem_document(
        "no-lidar-data", "No LiDAR data", 422, "the recording has no sensor_msgs/PointCloud2 topic"
    )
    with db.transaction() as session:
        repository.fail_run(session, run_id, problem, lease_owner="w")
    with db.session() as session:
        run = session.get(Run, run_id)
    assert run is not None and run.status == RunStatus.FAILED
    assert run.error == problem and run.finished_at is not None and run.lease_owner is None
    with pytest.raises(repository.RunFinishedError), db.transaction() as session:
        repository.fail_run(session, run_id, problem)


def test_latest_calibration_is_the_newest_passed_result(db: Database) -> None:
    first, second, third = (queued_run(db) for _ in range(3))
    for run_id, passed in ((first, True), (second, True), (third, False)):
        with db.transaction() as session:
            repository.store_result(session, run_id, result_document(passed=passed))
    with db.session() as session:
        latest = repository.latest_calibration(session, "R1")
        assert latest is not None and latest.run_id == second
        assert repository.latest_calibration(session, "R2") is None


def test_tolerance_profile_for_prefers_the_model_then_the_default(db: Database) -> None:
    with db.transaction() as session:
        repository.put_tolerance_profile(
            session,
            "strict",
            robot_model="mk2",
            is_default=False,
            limits={"max_metric_error_m": 0.002},
            design_extrinsics=None,
        )
        repository.put_tolerance_profile(
            session,
            "fallback",
            robot_model=None,
            is_default=True,
            limits={},
            design_extrinsics=None,
        )
        mk2, _ = repository.put_robot(session, "A", model="mk2", metadata={})
        mk1, _ = repository.put_robot(session, "B", model="mk1", metadata={})
        bare, _ = repository.put_robot(session, "C", model=None, metadata={})
        found = [repository.tolerance_profile_for(session, r) for r in (mk2, mk1, bare)]
        assert [p.name if p else None for p in found] == ["strict", "fallback", "fallback"]


def test_only_one_default_profile(db: Database) -> None:
    with db.transaction() as session:
        for name in ("a", "b"):
            repository.put_tolerance_profile(
                session, name, robot_model=None, is_default=True, limits={}, design_extrinsics=None
            )
    with db.session() as session:
        defaults = [p.name for p in repository.list_tolerance_profiles(session) if p.is_default]
        assert defaults == ["b"]
