"""ShmStorage: `MemoryStorage` whose ring arrays live in the shard's shared-memory segment.

Readers in other processes copy rows straight out of the segment (`shm_rows.read_rows`)
while the shard writes, so every write the shard makes to a stored row is bracketed by its
slot's generation counter (`gen`, odd while the row is being written): a reader that
overlapped a write sees the counter differ or odd and draws that row again. Rows that
clients write into reserved slots need no bracket: those slots are out of the index (stamp
-1) from their reservation until their commit.
"""
from __future__ import annotations

import numpy as np

from wmdist.replay.batch import SequenceBatch
from wmdist.replay.shm import ShmSegment
from wmdist.replay.storage_memory import MemoryStorage


class ShmStorage(MemoryStorage):
    durable = False  # the shard re-attaches the segment itself; checkpoints hold the arrays as before

    def __init__(self, segment: ShmSegment) -> None:  # no super().__init__: the arrays exist already
        self.segment = segment
        self.capacity, self.T = segment.mask.shape
        self.data = dict(segment.data)  # field -> [C, T, ...] view
        self.mask = segment.mask  # [C, T] view
        self.gen = segment.meta["gen"]  # [C] view

    def _bracket(self, slots: np.ndarray, write) -> None:
        s = np.unique(np.asarray(slots, np.int64))
        self.gen[s] += 1  # odd: a reader overlapping this write rejects the row
        try:
            write()
        finally:
            self.gen[s] += 1

    def write(self, slots: np.ndarray, batch: SequenceBatch, meta: dict[str, np.ndarray]) -> None:
        self._bracket(slots, lambda: MemoryStorage.write(self, slots, batch, meta))

    def write_fields(self, slots: np.ndarray, fields: dict[str, np.ndarray]) -> None:
        self._bracket(slots, lambda: MemoryStorage.write_fields(self, slots, fields))

    def load_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        self._bracket(np.arange(self.capacity), lambda: MemoryStorage.load_arrays(self, arrays))

    def close(self) -> None:
        self.segment.unlink()
