"""The processes that run the pipeline: one long-lived child per slot, one job at a time each.

Not `concurrent.futures.ProcessPoolExecutor`: when one of its children dies, the whole pool breaks
and every run in it fails, while the queue must blame only the run whose process died (and the
parent must be able to stop one child whose lease was lost). Children come from a fork server
(the parent has threads, which a plain `fork` does not survive) that has imported the job's module
once, so a replacement child starts in milliseconds rather than re-importing numpy, scipy and
Open3D. BLAS and OpenMP are pinned to one thread per process: under load, default BLAS threading
made a 0.1 ms solve take 110 ms (DESIGN.md).
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import multiprocessing
import os
import signal
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

from workers.policy import Failure, classify

log = logging.getLogger(__name__)

BLAS_THREAD_VARIABLES = (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
_ENVIRONMENT_LOCK = threading.Lock()

Report = Callable[[str, float], None]
"""How a job tells the parent which stage it has reached and how far along it is (0..1)."""
Job = Callable[[Any, Report], Any]
"""A job function: (spec, report) -> result, run in a child; it is named `module:function`."""


@dataclass(frozen=True)
class Stage:
    name: str
    progress: float


@dataclass(frozen=True)
class Done:
    result: Any


@dataclass(frozen=True)
class Failed:
    failure: Failure
    traceback: str


@dataclass(frozen=True)
class Broken:
    """The child cannot load its job function: no run can succeed here (a deployment error)."""

    traceback: str


Message = Stage | Done | Failed | Broken


class PoolError(Exception):
    """The pool cannot run its jobs at all."""


@dataclass
class Slot:
    """One child process and the job it is running, if any (`job` is the parent's handle)."""

    index: int
    process: multiprocessing.process.BaseProcess
    connection: Connection
    job: Any = None
    stage: str | None = None
    started: float = field(default_factory=time.monotonic)

    @property
    def busy(self) -> bool:
        return self.job is not None


class Pool:
    """`size` slots running the job function `target` ("module:function")."""

    def __init__(self, size: int, target: str) -> None:
        if size < 1:
            raise ValueError("a pool needs at least one slot")
        self.target = target
        self._context = multiprocessing.get_context("forkserver")
        # Takes effect when the fork server starts (the first child of this process). With
        # `__main__` preloaded, children do not import the main module again each. Children
        # inherit the environment the fork server started with, not later changes to it.
        self._context.set_forkserver_preload(["__main__", __name__, target.partition(":")[0]])
        self.slots = [self._spawn(index) for index in range(size)]

    def _spawn(self, index: int) -> Slot:
        parent_end, child_end = self._context.Pipe()
        process = self._context.Process(
            target=_child_main,
            args=(child_end, self.target),
            name=f"fleetcal-pipeline-{index}",
            daemon=True,
        )
        with _pinned_blas_threads():
            process.start()
        child_end.close()
        return Slot(index, process, parent_end)

    def idle(self) -> list[Slot]:
        return [slot for slot in self.slots if not slot.busy]

    def busy(self) -> list[Slot]:
        return [slot for slot in self.slots if slot.busy]

    def start(self, slot: Slot, job: Any, spec: Any) -> None:
        """Hand `spec` to the idle `slot`; `job` is what the parent remembers it by."""
        slot.connection.send(spec)
        slot.job, slot.stage, slot.started = job, None, time.monotonic()

    def finish(self, slot: Slot) -> None:
        slot.job, slot.stage = None, None

    def waitables(self) -> list[Any]:
        return [slot.connection for slot in self.slots] + [
            slot.process.sentinel for slot in self.slots
        ]

    def receive(self, slot: Slot) -> Message | None:
        """The child's next message, or None if it died (its pipe closed)."""
        try:
            message: Message = slot.connection.recv()
        except (EOFError, OSError):
            return None
        if isinstance(message, Stage):
            slot.stage = message.name
        return message

    def replace(self, slot: Slot) -> Slot:
        """Kill `slot`'s child (if alive) and start a fresh one in its place."""
        self._kill(slot)
        slot.connection.close()
        fresh = self._spawn(slot.index)
        self.slots[slot.index] = fresh
        return fresh

    def slot_of(self, waitable: Any) -> Slot | None:
        for slot in self.slots:
            if waitable is slot.connection or waitable == slot.process.sentinel:
                return slot
        return None

    def close(self) -> None:
        """Stop every child: idle ones exit when told, busy ones are killed."""
        for slot in self.slots:
            if slot.busy:
                self._kill(slot)
                continue
            with contextlib.suppress(OSError, ValueError):
                slot.connection.send(None)
        deadline = time.monotonic() + 5
        for slot in self.slots:
            slot.process.join(max(0.0, deadline - time.monotonic()))
            if slot.process.is_alive():
                self._kill(slot)
            slot.connection.close()

    @staticmethod
    def _kill(slot: Slot) -> None:
        if slot.process.is_alive():
            slot.process.kill()
        slot.process.join(5)


def death_message(slot: Slot) -> str:
    """Why a child is gone, for the run's failure: its signal or exit code."""
    # Its pipe may report the death before the fork server reports the exit status.
    slot.process.join(5)
    code = slot.process.exitcode
    if code is not None and code < 0:
        try:
            how = f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            how = f"was killed by signal {-code}"
        if code == -signal.SIGKILL:
            how += " (out of memory, or killed by hand)"
    else:
        how = f"exited with code {code}"
    return f"the process running the pipeline {how}"


@contextlib.contextmanager
def _pinned_blas_threads() -> Iterator[None]:
    """Set the BLAS/OpenMP thread variables while a child starts: the fork server starts with the
    first child and imports numpy (whose BLAS reads them then), and every child inherits them."""
    with _ENVIRONMENT_LOCK:
        saved = {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES}
        os.environ.update(dict.fromkeys(BLAS_THREAD_VARIABLES, "1"))
        try:
            yield
        finally:
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value


def _die_with_parent() -> None:
    """Ask Linux to kill this child when its parent, the fork server, exits, which it does when
    the worker dies: a killed worker leaves no orphan computing a result nobody will store."""
    with contextlib.suppress(OSError, AttributeError):
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)


def _child_main(connection: Connection, target: str) -> None:
    # The parent decides when a run stops: Ctrl-C in a terminal or a group-wide SIGTERM must not
    # kill a child mid-run behind its back (it gives the run back, or waits for it).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _die_with_parent()
    module_name, _, function_name = target.partition(":")
    try:
        job: Job = getattr(importlib.import_module(module_name), function_name)
    except Exception:
        connection.send(Broken(traceback.format_exc()))
        return
    stage: list[str | None] = [None]

    def report(name: str, progress: float) -> None:
        stage[0] = name
        connection.send(Stage(name, progress))

    while True:
        try:
            spec = connection.recv()
        except EOFError:
            return
        if spec is None:
            return
        stage[0] = None
        try:
            message: Message = Done(job(spec, report))
        except Exception as exc:
            message = Failed(classify(exc, stage=stage[0]), traceback.format_exc())
        try:
            connection.send(message)
        except (BrokenPipeError, EOFError):
            return
