"""The runs a worker holds (claimed, not yet ended) and those of them whose lease it lost. The
main loop and the heartbeat thread share them, hence the lock."""

from __future__ import annotations

import threading
import uuid

from workers.queue import Claim


class Holdings:
    def __init__(self) -> None:
        self._held: dict[uuid.UUID, Claim] = {}
        self._lost: set[uuid.UUID] = set()
        self._lock = threading.Lock()

    def hold(self, claim: Claim) -> None:
        with self._lock:
            self._held[claim.run_id] = claim

    def all(self) -> list[Claim]:
        with self._lock:
            return list(self._held.values())

    def run_ids(self) -> set[uuid.UUID]:
        with self._lock:
            return set(self._held)

    def mark_lost(self, claim: Claim) -> None:
        """The run's lease is gone (reaped, or finished elsewhere), if it is still held."""
        with self._lock:
            if claim.run_id in self._held:
                self._lost.add(claim.run_id)

    def lost(self) -> set[uuid.UUID]:
        with self._lock:
            return set(self._lost)

    def release(self, claim: Claim) -> None:
        with self._lock:
            self._held.pop(claim.run_id, None)
            self._lost.discard(claim.run_id)
