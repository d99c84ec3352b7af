"""Reservations: one client's stock of slots reserved in one shared-memory shard.

The client asks for slots ahead (`ShmShard.reserve`, not waited for), writes rows into
them and commits them in the segment (`shm_rows.commit_rows`), so an insert needs no shard
call while the stock lasts (`wmdist/runtime/replay_shm.py`). Slots are used oldest first and only while younger than `shard_shm.LEASE_USE_SECONDS` (counted from
the request), well inside the lease after which the shard may hand them out again.
"""
from __future__ import annotations

import numpy as np


class Reservations:
    def __init__(self) -> None:
        self.slots = np.zeros(0, np.int64)  # [n]
        self.stamps = np.zeros(0, np.int64)  # [n] write id of each reserved slot
        self.born = np.zeros(0, np.float64)  # [n] when each was asked for (monotonic seconds)

    def __len__(self) -> int:
        return int(self.slots.size)

    def add(self, got: dict, at: float) -> None:
        """Append a `ShmShard.reserve` result asked for at `at`."""
        n = len(got["slots"])
        self.slots = np.concatenate([self.slots, np.asarray(got["slots"], np.int64)])
        self.stamps = np.concatenate([self.stamps, np.asarray(got["stamps"], np.int64)])
        self.born = np.concatenate([self.born, np.full(n, at)])

    def expire(self, before: float) -> None:
        """Forget slots asked for before `before` (their shard will reclaim them)."""
        n = int(np.searchsorted(self.born, before))
        if n:
            self.take(n)

    def take(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The oldest k -> (slots [k], stamps [k]); they leave the stock."""
        k = min(k, len(self))
        out = self.slots[:k], self.stamps[:k]
        self.slots, self.stamps, self.born = self.slots[k:], self.stamps[k:], self.born[k:]
        return out
