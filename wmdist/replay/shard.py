"""ReplayShard: one shard's index, sampler and storage (no Ray; the actor only forwards).

Per slot the shard keeps a small index (`stamp` = write id or -1 if empty, policy version,
episode, real steps) and a sum tree of sampling masses (1 per occupied slot for uniform;
p^alpha for prioritized). Slots are a FIFO ring: write id w goes to slot w % capacity, so
the oldest sequence is evicted first. A write-back names (slot, stamp); if the slot has been
rewritten since (stamp differs) it is dropped and counted, never applied to other data.
All methods take one lock, so a threaded actor can serve them concurrently.
"""
from __future__ import annotations

import json
import os
import threading

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch, check_field
from wmdist.replay.storage_memory import MemoryStorage
from wmdist.replay.sumtree import SumTree

DROP_REASONS = ("stale_writeback", "stale_priority", "evicted", "corrupt", "policy_lag")


class ReplayShard:
    def __init__(self, fields: dict[str, FieldSpec], seq_len: int, capacity: int, sampler: str = "uniform",
                 alpha: float = 0.6, storage=None, seed: int = 0, shard_id: int = 0) -> None:
        if sampler not in ("uniform", "prioritized"):
            raise ValueError(f"replay sampler must be 'uniform' or 'prioritized', got {sampler!r}")
        if capacity < 1:
            raise ValueError(f"replay shard capacity must be >= 1 sequence, got {capacity}")
        self.fields, self.T, self.capacity = dict(fields), seq_len, capacity
        self.prioritized = sampler == "prioritized"
        self.alpha = float(alpha)
        self.shard_id = shard_id
        self.storage = storage if storage is not None else MemoryStorage(fields, capacity, seq_len)
        self.rng = np.random.default_rng(seed)
        self.lock = threading.RLock()
        C = capacity
        self.stamp = np.full(C, -1, np.int64)  # [C] write id of the slot's sequence, -1 = empty
        self.version = np.zeros(C, np.int64)  # [C] oldest policy version in the sequence
        self.episode = np.zeros(C, np.int64)  # [C]
        self.steps = np.zeros(C, np.int64)  # [C] real (mask=1) steps
        self.priority = np.zeros(C, np.float64)  # [C] raw priorities (before alpha)
        self.tree = SumTree(C)
        self.count = 0  # sequences ever written (next write id)
        self.max_priority = 1.0
        self.counters = {"inserts": 0, "samples": 0, **{f"drops_{r}": 0 for r in DROP_REASONS}}
        if getattr(self.storage, "durable", False):
            self.reload()

    # -- index --------------------------------------------------------------------------
    def _mass(self, p: np.ndarray) -> np.ndarray:
        return np.power(np.maximum(p, 1e-8), self.alpha) if self.prioritized else np.ones_like(p)

    def reload(self) -> None:
        """Rebuild index and priorities from durable storage (after a restart)."""
        with self.lock:
            idx, count, corrupt = self.storage.load()
            for k in ("stamp", "version", "episode", "steps", "priority"):
                getattr(self, k)[:] = idx[k]
            live = self.stamp >= 0
            self.priority[live & (self.priority <= 0)] = 1.0 if not self.prioritized else self.priority[live].max(initial=1.0)
            self.count = count
            self.max_priority = float(self.priority[live].max(initial=1.0))
            self.tree = SumTree(self.capacity)
            slots = np.flatnonzero(live)
            self.tree.set(slots, self._mass(self.priority[slots]))
            self.counters["drops_corrupt"] += corrupt

    @property
    def size_sequences(self) -> int:
        return int((self.stamp >= 0).sum())

    @property
    def size_steps(self) -> int:
        return int(self.steps[self.stamp >= 0].sum())

    # -- insert -------------------------------------------------------------------------
    def insert(self, batch: SequenceBatch, min_version: int | None = None) -> int:
        """Store complete windows (validated); returns real steps stored."""
        batch.validate(self.fields, self.T)
        with self.lock:
            if min_version is not None and len(batch):
                keep = batch.version >= min_version
                self.counters["drops_policy_lag"] += int((~keep).sum())
                if not keep.all():
                    batch = batch.select(np.flatnonzero(keep))
            n = len(batch)
            if n == 0:
                return 0
            if n > self.capacity:  # only the newest `capacity` would survive anyway
                self.counters["drops_evicted"] += n - self.capacity
                batch = batch.select(np.arange(n - self.capacity, n))
                self.count += n - self.capacity
                n = self.capacity
            ids = self.count + np.arange(n, dtype=np.int64)
            slots = ids % self.capacity
            self.counters["drops_evicted"] += int((self.stamp[slots] >= 0).sum())
            steps = batch.mask.sum(axis=1).astype(np.int64)
            prio = np.full(n, self.max_priority)  # new items at the current max priority
            meta = {"stamp": ids, "version": batch.version, "episode": batch.episode_id, "steps": steps,
                    "priority": prio}
            self.storage.write(slots, batch, meta)  # durable before the index sees it
            self.stamp[slots], self.version[slots] = ids, batch.version
            self.episode[slots], self.steps[slots], self.priority[slots] = batch.episode_id, steps, prio
            self.tree.set(slots, self._mass(prio))
            self.count += n
            self.counters["inserts"] += n
            return int(steps.sum())

    # -- sample -------------------------------------------------------------------------
    def mass(self) -> tuple[int, float, int]:
        """(sequences, total sampling mass, real steps) for the client's cross-shard split."""
        with self.lock:
            return self.size_sequences, self.tree.total, self.size_steps

    def sample(self, k: int, beta: float = 0.0, global_count: int = 0, global_mass: float = 0.0) -> dict:
        """k draws; `is_weight` = (N P(i))^-beta with the union's N and mass (not normalised).

        Returns {"data", "mask" [k, T] bool, "is_weight" [k], "slots" [k], "stamps" [k]}.
        """
        if k < 0:
            raise ValueError(f"sample size must be >= 0, got {k}")
        with self.lock:
            out_data = {f: np.zeros((k, self.T, *s.shape), dtype=s.dtype) for f, s in self.fields.items()}
            out_mask = np.zeros((k, self.T), dtype=bool)
            slots = np.zeros(k, np.int64)
            todo = np.arange(k)
            while todo.size:
                if self.tree.total <= 0:
                    raise ValueError(f"replay shard {self.shard_id} is empty")
                s = self.tree.sample(todo.size, self.rng)
                data, mask, bad = self.storage.read(s)
                good = np.setdiff1d(np.arange(todo.size), bad)
                for f in out_data:
                    out_data[f][todo[good]] = data[f][good]
                out_mask[todo[good]] = mask[good]
                slots[todo[good]] = s[good]
                if bad.size:  # corrupt in storage: forget the slot, count it, draw again
                    dead = np.unique(s[bad])
                    self.counters["drops_corrupt"] += dead.size
                    self.stamp[dead] = -1
                    self.tree.set(dead, np.zeros(dead.size))
                todo = todo[bad]
            if self.prioritized and beta > 0:
                n = global_count or self.size_sequences
                total = global_mass or self.tree.total
                p = self.tree.get(slots) / total  # P(i), Schaul et al. 2016 Eq. 1
                w = np.power(n * p, -beta)  # w_i = (N P(i))^-beta, Sec. 3.4
            else:
                w = np.ones(k)
            self.counters["samples"] += k
            return {"data": out_data, "mask": out_mask, "is_weight": w.astype(np.float32),
                    "slots": slots, "stamps": self.stamp[slots].copy()}

    # -- write-back ---------------------------------------------------------------------
    def _fresh(self, slots: np.ndarray, stamps: np.ndarray, reason: str) -> np.ndarray:
        slots = np.asarray(slots, np.int64)
        stamps = np.asarray(stamps, np.int64)
        if slots.shape != stamps.shape or slots.ndim != 1:
            raise ValueError("write-back: keys and stamps must be 1-D arrays of the same length")
        if slots.size and (slots.min() < 0 or slots.max() >= self.capacity):
            raise ValueError(f"write-back: slot out of range [0, {self.capacity})")
        ok = (self.stamp[slots] == stamps) & (stamps >= 0)
        self.counters[f"drops_{reason}"] += int((~ok).sum())
        return ok

    def update_priorities(self, slots: np.ndarray, stamps: np.ndarray, priorities: np.ndarray) -> int:
        """Set raw priorities where the stamp still matches; returns how many were applied."""
        pr = np.asarray(priorities, np.float64)
        if pr.shape != np.shape(slots):
            raise ValueError(f"priorities shape {pr.shape} != keys shape {np.shape(slots)}")
        if not np.all(np.isfinite(pr)) or (pr.size and pr.min() < 0):
            raise ValueError("priorities must be finite and >= 0")
        with self.lock:
            ok = self._fresh(slots, stamps, "stale_priority")
            s, p = np.asarray(slots, np.int64)[ok], pr[ok]
            if s.size == 0:
                return 0
            self.priority[s] = p
            self.max_priority = max(self.max_priority, float(p.max()))
            self.storage.write_priorities(s, p)
            self.tree.set(s, self._mass(p))
            return int(s.size)

    def write_back(self, slots: np.ndarray, stamps: np.ndarray, fields: dict[str, np.ndarray]) -> int:
        """Overwrite stored fields `[B, T, ...]` where the stamp still matches; returns rows applied."""
        B = len(slots)
        for name, arr in fields.items():
            if name not in self.fields:
                raise ValueError(f"write-back: unknown field '{name}' (declared: {sorted(self.fields)})")
            check_field(name, arr, self.fields[name], (B, self.T))
        with self.lock:
            ok = self._fresh(slots, stamps, "stale_writeback")
            rows = np.flatnonzero(ok)
            if rows.size:
                s = np.asarray(slots, np.int64)[rows]
                self.storage.write_fields(s, {k: v[rows] for k, v in fields.items()})
            return int(rows.size)

    # -- stats and checkpoints ----------------------------------------------------------
    def stats(self) -> dict[str, float]:
        with self.lock:
            index = sum(getattr(self, k).nbytes for k in self._INDEX) + self.tree.tree.nbytes
            return {"size_steps": float(self.size_steps), "size_sequences": float(self.size_sequences),
                    "capacity_sequences": float(self.capacity),
                    "bytes": float(self.storage.nbytes + index), **{k: float(v) for k, v in self.counters.items()}}

    _INDEX = ("stamp", "version", "episode", "steps", "priority")

    def save(self, path: str) -> None:
        """Write index, priorities, counters and (memory storage) the arrays to `path` (.npz)."""
        with self.lock:
            arrays = {"i_" + k: getattr(self, k) for k in self._INDEX}
            if not self.storage.durable:
                arrays.update(self.storage.arrays())
            scalars = {"count": self.count, "max_priority": self.max_priority, "counters": self.counters,
                       "capacity": self.capacity, "seq_len": self.T}
            arrays["scalars"] = np.frombuffer(json.dumps(scalars).encode(), dtype=np.uint8)
            tmp = path + ".tmp.npz"
            np.savez(tmp, **arrays)
            os.replace(tmp, path)

    def restore(self, path: str) -> None:
        """Load what `save` wrote (never unpickles). Durable storage re-reads redis instead."""
        with self.lock, np.load(path, allow_pickle=False) as z:
            scalars = json.loads(bytes(z["scalars"]).decode())
            if scalars["capacity"] != self.capacity or scalars["seq_len"] != self.T:
                raise ValueError(f"replay checkpoint {path} has capacity {scalars['capacity']} / seq_len "
                                 f"{scalars['seq_len']}, this shard {self.capacity} / {self.T}")
            if self.storage.durable:
                self.reload()
                return
            self.storage.load_arrays({k: z[k] for k in z.files if not k.startswith("i_") and k != "scalars"})
            for k in self._INDEX:
                getattr(self, k)[:] = z["i_" + k]
            self.count, self.max_priority = int(scalars["count"]), float(scalars["max_priority"])
            self.counters.update({k: int(v) for k, v in scalars["counters"].items()})
            self.tree = SumTree(self.capacity)
            live = np.flatnonzero(self.stamp >= 0)
            self.tree.set(live, self._mass(self.priority[live]))

    def close(self) -> None:
        self.storage.close()
