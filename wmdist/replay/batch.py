"""The two record types that cross the replay boundary: what is inserted and what is sampled."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.codec import check_dtype


@dataclass
class SequenceBatch:
    """N complete windows of T steps, as the writer emits them and shards store them."""

    data: dict[str, np.ndarray]  # field -> [N, T, ...]
    mask: np.ndarray  # [N, T] bool: 1 = real step, 0 = padding after the episode's end
    version: np.ndarray  # [N] int64: oldest policy version inside each window
    episode_id: np.ndarray  # [N] int64: writer-local episode counter

    def __len__(self) -> int:
        return int(self.mask.shape[0])

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.data.values()) + self.mask.nbytes

    def select(self, rows: np.ndarray) -> "SequenceBatch":
        return SequenceBatch({k: v[rows] for k, v in self.data.items()}, self.mask[rows],
                             self.version[rows], self.episode_id[rows])

    def concat(self, other: "SequenceBatch") -> "SequenceBatch":
        """Both batches' windows, this one's first."""
        return SequenceBatch({k: np.concatenate([v, other.data[k]]) for k, v in self.data.items()},
                             np.concatenate([self.mask, other.mask]), np.concatenate([self.version, other.version]),
                             np.concatenate([self.episode_id, other.episode_id]))

    def validate(self, fields: dict[str, FieldSpec], seq_len: int) -> None:
        """Raise ValueError naming the first field that is missing or has a wrong dtype/shape."""
        n = self.mask.shape[0] if getattr(self.mask, "ndim", 0) >= 1 else -1
        if not isinstance(self.mask, np.ndarray) or self.mask.shape != (n, seq_len):
            raise ValueError(f"replay insert: mask must be [N, {seq_len}], got {getattr(self.mask, 'shape', None)}")
        for name, arr, want in (("version", self.version, (n,)), ("episode_id", self.episode_id, (n,))):
            if not isinstance(arr, np.ndarray) or arr.shape != want or arr.dtype.kind not in "iu":
                raise ValueError(f"replay insert: {name} must be an int array of shape {want}")
        for name, spec in fields.items():
            if name not in self.data:
                raise ValueError(f"replay insert: field '{name}' is missing")
            check_field(name, self.data[name], spec, (n, seq_len))
        extra = set(self.data) - set(fields)
        if extra:
            raise ValueError(f"replay insert: unknown field '{sorted(extra)[0]}' (declared: {sorted(fields)})")


@dataclass
class Sample:
    """B sequences drawn from the union of all shards."""

    data: dict[str, np.ndarray]  # field -> [B, T, ...]
    mask: np.ndarray  # [B, T] float32
    is_weight: np.ndarray  # [B] float32, max-normalised importance weights (1 for uniform)
    keys: np.ndarray  # [B] int64: shard << 40 | slot (opaque; pass back for write-back)
    stamps: np.ndarray  # [B] int64: write id of each slot when sampled (opaque)
    age: np.ndarray | None = None  # [B, T] int64: transitions stored after each step (`step_ages`)

    def as_batch(self) -> dict[str, np.ndarray]:
        """The dict `Learner.update` takes: fields plus mask and is_weight."""
        return {**self.data, "mask": self.mask, "is_weight": self.is_weight}


def check_field(name: str, arr: object, spec: FieldSpec, lead: tuple[int, ...]) -> None:
    """One clear ValueError if `arr` is not a `spec.dtype` array of shape `lead + spec.shape`."""
    if not isinstance(arr, np.ndarray):
        raise ValueError(f"field '{name}': expected a numpy array, got {type(arr).__name__}")
    check_dtype(arr.dtype, f"field '{name}'")
    if arr.dtype != np.dtype(spec.dtype):
        raise ValueError(f"field '{name}': dtype {arr.dtype.name}, expected {spec.dtype}")
    want = tuple(lead) + tuple(spec.shape)
    if arr.shape != want:
        raise ValueError(f"field '{name}': shape {arr.shape}, expected {want}")


KEY_SHIFT = 40  # keys = shard << KEY_SHIFT | slot


def make_keys(shard: int | np.ndarray, slots: np.ndarray) -> np.ndarray:
    return (np.asarray(shard, dtype=np.int64) << KEY_SHIFT) | np.asarray(slots, dtype=np.int64)


def split_keys(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    keys = np.asarray(keys, dtype=np.int64)
    return keys >> KEY_SHIFT, keys & ((1 << KEY_SHIFT) - 1)


def step_ages(newer: np.ndarray, mask: np.ndarray, shards: int) -> np.ndarray:
    """[B, T] int64 age of each step in transitions stored after it: newer [B] real steps its
    shard placed after the window, plus the window's own later steps, times the number of
    shards (episodes are hashed evenly onto them; exact with one shard). Padding gets the age
    of the window's last real step."""
    real = np.asarray(mask).astype(bool)  # [B, T]
    n = real.sum(1)  # [B]
    t = np.arange(real.shape[1])[None, :]
    within = np.maximum(n[:, None] - 1 - t, 0)  # [B, T] later steps of the same window
    return ((np.asarray(newer, np.int64)[:, None] + within) * shards).astype(np.int64)
