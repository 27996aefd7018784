"""Migration 0002 on a database holding results: each existing result and extrinsics row is
accepted exactly when it passed (the calibration in use does not change on upgrade)."""

from __future__ import annotations

import uuid

from sqlalchemy import select

from service import repository
from service.db import Database
from service.models import LidarExtrinsic, Result
from tests.service.documents import result_document
from tests.service.uploads import new_upload


def test_existing_results_are_accepted_as_they_passed(unmigrated_db: Database) -> None:
    unmigrated_db.upgrade()
    runs = {passed: uuid.uuid4() for passed in (True, False)}
    with unmigrated_db.transaction() as session:
        for passed, run_id in runs.items():
            repository.record_upload(session, new_upload("R1", run_id=run_id), create_robot=True)
            repository.store_result(session, run_id, result_document(passed=passed))
    # Back to 0001 with the rows in place (the column goes), then up again (it is filled in).
    unmigrated_db.downgrade("0001")
    unmigrated_db.upgrade()
    with unmigrated_db.session() as session:
        accepted = dict(session.execute(select(Result.run_id, Result.accepted)).tuples().all())
        rows = session.execute(select(LidarExtrinsic.run_id, LidarExtrinsic.accepted)).all()
    assert accepted == {runs[True]: True, runs[False]: False}
    assert rows and all(flag == (run_id == runs[True]) for run_id, flag in rows)
