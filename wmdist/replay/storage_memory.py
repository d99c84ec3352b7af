"""In-memory storage: one preallocated ring array per field, `[capacity, T, ...]`.

No Python object per step or per sequence: a stored sequence is a row of each array, so
memory is the raw array bytes plus a bool mask `[capacity, T]` (1 byte per step) and the
shard's small per-slot index. Checkpoints are plain `.npz` files loaded with
`allow_pickle=False`.
"""
from __future__ import annotations

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch


class MemoryStorage:
    durable = False

    def __init__(self, fields: dict[str, FieldSpec], capacity: int, seq_len: int) -> None:
        self.fields, self.capacity, self.T = dict(fields), capacity, seq_len
        # np.zeros maps lazily-zeroed pages: memory is paid as slots fill
        self.data = {k: np.zeros((capacity, seq_len, *s.shape), dtype=s.dtype) for k, s in fields.items()}
        self.mask = np.zeros((capacity, seq_len), dtype=bool)  # [C, T]

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.data.values()) + self.mask.nbytes

    def write(self, slots: np.ndarray, batch: SequenceBatch, meta: dict[str, np.ndarray]) -> None:
        for k, a in self.data.items():
            a[slots] = batch.data[k]
        self.mask[slots] = batch.mask

    def read(self, slots: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """-> (fields [B, T, ...], mask [B, T] bool, corrupt row indices [0])"""
        return ({k: a[slots] for k, a in self.data.items()}, self.mask[slots], np.zeros(0, np.int64))

    def write_fields(self, slots: np.ndarray, fields: dict[str, np.ndarray]) -> None:
        for k, v in fields.items():
            self.data[k][slots] = v

    def drop(self, slots: np.ndarray) -> None:
        pass  # rows in memory never go bad

    def write_priorities(self, slots: np.ndarray, priorities: np.ndarray) -> None:
        pass  # the shard's sum tree is the only copy; it goes into checkpoints

    def arrays(self) -> dict[str, np.ndarray]:
        """Everything to checkpoint, by name."""
        return {**{"f_" + k: a for k, a in self.data.items()}, "mask": self.mask}

    def load_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Load checkpointed rows: each array holds the first n <= capacity slots (older
        checkpoints: all of them); the slots after them are left as they are (not live)."""
        for name, dst in self.arrays().items():
            if name not in arrays:
                raise ValueError(f"replay checkpoint is missing array '{name}'")
            src = arrays[name]
            if src.shape[1:] != dst.shape[1:] or len(src) > len(dst) or src.dtype != dst.dtype:
                raise ValueError(f"replay checkpoint array '{name}' is {src.dtype}{src.shape}, expected {dst.dtype}"
                                 f"[<={dst.shape[0]}, {', '.join(map(str, dst.shape[1:]))}]")
            dst[:len(src)] = src  # the rest is never read: no live index entry names it

    def close(self) -> None:
        pass
