"""Workers killed with SIGKILL, on SQLite and PostgreSQL, with the real pipeline on the `tiny`
scenario: killed in each stage of a run, the run is taken up again after its lease and finishes
once; one of two workers killed while the other calibrates, neither run is lost or doubled."""

from __future__ import annotations

import uuid
from functools import partial
from pathlib import Path
from typing import Any

import pytest

from pipeline.calibrate import STAGES
from service import repository
from service.db import Database
from service.models import RunStatus
from service.settings import Settings
from tests.reliability.harness import (
    QUICK,
    Process,
    processes,
    run_row,
    start_worker,
    store_run,
    stored_once,
    stored_results,
    wait_for,
)
from tests.reliability.jobs import PAUSED_CALIBRATION

pytestmark = pytest.mark.slow

WORKER_STAGES = ("download", "read", *STAGES, "drift", "report")
"""Every stage a run goes through in the worker (`drift`: against the model's design)."""
LEASE_S = 5
"""Short, for a test that waits out a dead worker's lease seven times; long enough that a living
worker's heartbeat, delayed by SQLite's write lock on a loaded machine, never lets it lapse (each
worker here runs beside the one about to be killed, and would reap its runs)."""
WAIT_S = 240  # only keeps a broken worker from hanging CI; never a timing assertion
TINY_FRAMES = ("lidar_front", "lidar_rear")


@pytest.fixture
def db(settings: Settings) -> Any:
    database = Database.from_settings(settings)
    with database.transaction() as session:
        # A design to compare with, so that end-of-line runs go through the drift stage too.
        pose = {"translation": [0.0, 0.0, 0.0], "rotation_xyzw": [0.0, 0.0, 0.0, 1.0]}
        repository.put_tolerance_profile(
            session,
            "tiny",
            robot_model="tiny-bot",
            is_default=False,
            limits={"max_metric_error_m": 0.5},
            design_extrinsics=dict.fromkeys(TINY_FRAMES, pose),
        )
        repository.put_robot(session, "R1", model="tiny-bot", metadata={})
    yield database
    database.dispose()


def short_lease(settings: Settings) -> Settings:
    return settings.model_copy(update={"run_lease_seconds": LEASE_S})


def held(db: Database, run_id: uuid.UUID, attempt: int, stage: str | None = None) -> bool:
    run = run_row(db, run_id)
    return (
        run.status == RunStatus.RUNNING
        and run.attempts == attempt
        and (stage is None or run.stage == stage)
    )


Stages = dict[str, tuple[str, ...]]
"""Run name -> the stages its worker is killed in, one per attempt."""


def test_a_worker_killed_in_each_stage_leaves_the_run_to_finish_once(
    settings: Settings, db: Database, tiny_recording: bytes, tmp_path: Path
) -> None:
    """Two runs share the stages: a worker calibrating both (two pipeline processes) is killed
    with run A in one stage and run B in another, its successor takes both up after their leases
    and is killed in the next two stages, and so on; the last one lets them finish."""
    settings = short_lease(settings)
    half = (len(WORKER_STAGES) + 1) // 2
    stages = {"A": WORKER_STAGES[:half], "B": WORKER_STAGES[half:]}
    runs = {
        name: store_run(
            settings,
            db,
            tiny_recording,
            config={**QUICK, "pause_at": {str(k): s for k, s in enumerate(names, start=1)}},
            max_attempts=half + 1,
        )
        for name, names in stages.items()
    }
    with processes() as workers:
        _kill_a_worker_per_attempt(workers, settings, db, runs, stages, tmp_path)

        def ended() -> bool:
            final = (RunStatus.SUCCEEDED, RunStatus.FAILED)
            return all(run_row(db, run).status in final for run in runs.values())

        wait_for("the last attempts", ended, WAIT_S)
        survivor = workers[-1]
        survivor.stop()
    for name, names in stages.items():
        run = run_row(db, runs[name])
        assert run.status == RunStatus.SUCCEEDED, (name, run.error, survivor.output())
        assert run.attempts == len(names) + 1, "one attempt per kill, and the one that finished"
        assert stored_once(db, runs[name])
    with db.session() as session:
        found = repository.get_run(session, runs["B"])
        assert found is not None and found[1] is not None
        document = found[1].document
    assert document["drift"]["against"] == "design" and document["report"]["images"]


def _kill_a_worker_per_attempt(
    workers: list[Process],
    settings: Settings,
    db: Database,
    runs: dict[str, uuid.UUID],
    stages: Stages,
    tmp_path: Path,
) -> None:
    """Start a worker, and at each attempt, once both runs are in that attempt's stages (with
    the next worker started and waiting), kill the one holding them; the last worker started
    is left to finish them."""
    both_held = partial(_both_held, db, runs, stages)
    log = tmp_path / "worker-1.log"
    workers.append(start_worker(settings, PAUSED_CALIBRATION, log, concurrency=2))
    for attempt in range(1, max(map(len, stages.values())) + 1):
        doomed = workers[-1]
        wait_for(f"attempt {attempt}", partial(both_held, attempt, False), WAIT_S)
        # The next worker starts while this one calibrates: it waits for the leases to lapse.
        log = tmp_path / f"worker-{attempt + 1}.log"
        workers.append(start_worker(settings, PAUSED_CALIBRATION, log, concurrency=2))
        in_stages = [names[attempt - 1] for names in stages.values() if attempt <= len(names)]
        wait_for(f"attempt {attempt} in {in_stages}", partial(both_held, attempt, True), WAIT_S)
        doomed.kill()
        assert both_held(attempt, True), "the kill neither ended nor released a run"
        for name, names in stages.items():
            if attempt <= len(names):
                assert stored_results(db, runs[name]) == (0, 0)


def _both_held(
    db: Database, runs: dict[str, uuid.UUID], stages: Stages, attempt: int, in_stage: bool
) -> bool:
    """Each run held at `attempt` (in its stage), or, past its stages, finished."""
    return all(
        held(db, runs[name], attempt, names[attempt - 1] if in_stage else None)
        if attempt <= len(names)
        else not in_stage or run_row(db, runs[name]).status == RunStatus.SUCCEEDED
        for name, names in stages.items()
    )


def test_one_of_two_workers_killed_while_the_other_calibrates(
    settings: Settings, db: Database, tiny_recording: bytes, tmp_path: Path
) -> None:
    """Worker 1 dies holding run A; worker 2, busy with run B, finishes B undisturbed, then takes A
    up after A's lease, and finishes it too: two results, one each."""
    settings = short_lease(settings)
    release = tmp_path / "release-b"
    with processes() as workers:
        run_a = store_run(
            settings, db, tiny_recording, config={**QUICK, "pause_at": {"1": "optimisation"}}
        )
        workers.append(start_worker(settings, PAUSED_CALIBRATION, tmp_path / "worker-1.log"))
        wait_for("worker 1 in run A", lambda: held(db, run_a, 1, "optimisation"), WAIT_S)
        run_b = store_run(
            settings,
            db,
            tiny_recording,
            config={**QUICK, "hold_at": {"1": ["rough_refinement", str(release)]}},
        )
        workers.append(start_worker(settings, PAUSED_CALIBRATION, tmp_path / "worker-2.log"))
        wait_for("worker 2 in run B", lambda: held(db, run_b, 1, "rough_refinement"), WAIT_S)
        workers[0].kill()
        release.touch()  # run B goes on, in worker 2, after worker 1 died
        final = (RunStatus.SUCCEEDED, RunStatus.FAILED)
        wait_for(
            "both runs",
            lambda: {run_row(db, r).status for r in (run_a, run_b)} <= set(final),
            WAIT_S,
        )
        workers[1].stop()
    a, b = run_row(db, run_a), run_row(db, run_b)
    assert b.status == RunStatus.SUCCEEDED and b.attempts == 1, (b.error, workers[1].output())
    assert a.status == RunStatus.SUCCEEDED and a.attempts == 2, (a.error, workers[1].output())
    assert a.lease_owner is None and b.lease_owner is None
    assert stored_once(db, run_a) and stored_once(db, run_b)
