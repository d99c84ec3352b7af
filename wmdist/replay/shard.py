"""ReplayShard: one shard's index, sampler and storage (no Ray; the actor only forwards).

Per slot the shard keeps a small index (`stamp` = write id or -1 if empty, policy version,
episode, real steps) and a sum tree of sampling masses (1 per occupied slot for uniform;
p^alpha for prioritized). Slots are a FIFO ring: write id w goes to slot w % capacity, so
the oldest sequence is evicted first. A write-back names (slot, stamp); if the slot has been
rewritten since (stamp differs) it is dropped and counted, never applied to other data.
All methods take one lock, so a threaded actor can serve them concurrently.

Age: the shard counts the real steps it has indexed (`clock`) and keeps, per slot, the
count when its window was placed (`born`). `sample` and `draw` return `newer` per draw: the
real steps indexed after that window. Step t of a window of n real steps then has age
newer + (n - 1 - t) in this shard's transitions (the client turns that into [B, T] ages,
`batch.step_ages`). Eviction is FIFO, so every step placed after a live one is live too:
after a restart the clock is rebuilt exactly from the live slots' stamps and steps.

Durable (redis) storage also takes inserts clients wrote themselves: they announce them in
the storage's pending list and `drain()` indexes them. Every read (`sample`, `draw`, `mass`,
`stats`, `save`) drains first, so a reader sees every insert acknowledged before its call.
"""
from __future__ import annotations

import json
import os
import threading
from typing import Any

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch, check_field
from wmdist.replay.draws import is_weights
from wmdist.replay.storage_memory import MemoryStorage
from wmdist.replay.sumtree import SumTree

# why a sequence or a write-back was not kept (`unacked`: records found in redis at restart
# whose insert was never acknowledged)
DROP_REASONS = ("stale_writeback", "stale_priority", "evicted", "corrupt", "policy_lag", "unacked")


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
        self.born = np.zeros(C, np.int64)  # [C] the clock when the slot's window was placed
        self.clock = 0  # real steps placed in this shard (the age clock)
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
            idx, count, drops = self.storage.load()
            for k in ("stamp", "version", "episode", "steps", "priority"):
                getattr(self, k)[:] = idx[k]
            live = self.stamp >= 0
            known = live & np.isfinite(self.priority)
            self.max_priority = float(self.priority[known].max(initial=1.0))
            self.priority[live & ~known] = self.max_priority  # no stored priority: treat as new
            self.priority[~live] = 0.0
            self.count = count
            self.tree = SumTree(self.capacity)
            slots = np.flatnonzero(live)
            self.tree.set(slots, self._mass(self.priority[slots]))
            self._rebuild_clock()
            for reason, n in drops.items():
                self.counters[f"drops_{reason}"] += n
            self.drain()  # inserts acknowledged but not yet indexed when the shard stopped

    def _rebuild_clock(self) -> None:
        """born / clock from the live slots in write order (exact: eviction is FIFO)."""
        live = np.flatnonzero(self.stamp >= 0)
        order = live[np.argsort(self.stamp[live], kind="stable")]
        steps = self.steps[order]
        self.born[order] = np.cumsum(steps) - steps
        self.clock = int(steps.sum())

    def newer(self, slots: np.ndarray) -> np.ndarray:
        """[k] real steps placed after each slot's window (its last step's age)."""
        slots = np.asarray(slots, np.int64)
        return (self.clock - self.born[slots] - self.steps[slots]).astype(np.int64)

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
            if n > self.capacity:  # only the newest `capacity` would survive anyway
                self._skip(n - self.capacity)
                batch = batch.select(np.arange(n - self.capacity, n))
            steps = batch.mask.sum(axis=1).astype(np.int64)
            return self._place(batch.version, batch.episode_id, steps,
                               lambda slots, meta: self.storage.write(slots, batch, meta))

    def insert_keys(self, keys: list[str], version: np.ndarray, episode: np.ndarray, steps: np.ndarray,
                    lag_drops: int = 0) -> int:
        """Index records a client already wrote to durable storage (redis direct path)."""
        if not self.storage.durable:
            raise ValueError("insert_keys needs a durable (redis) storage")
        if not (len(keys) == len(version) == len(episode) == len(steps)):
            raise ValueError("insert_keys: keys, version, episode and steps must have the same length")
        steps = np.asarray(steps, np.int64)
        if steps.size and (steps.min() < 1 or steps.max() > self.T):
            raise ValueError(f"insert_keys: steps must be in [1, {self.T}]")
        with self.lock:
            n = len(keys)
            if n > self.capacity:
                self.storage.discard_keys(list(keys[:n - self.capacity]))
                self._skip(n - self.capacity)
                keys, version, episode, steps = (x[n - self.capacity:] for x in (keys, version, episode, steps))
            stored = self._place(np.asarray(version, np.int64), np.asarray(episode, np.int64), steps,
                                 lambda slots, meta: self.storage.register(slots, list(keys), meta))
            self.counters["drops_policy_lag"] += int(lag_drops)  # counted once the insert succeeded
            return stored

    def drain(self, limit: int = 1024) -> int:
        """Index the inserts clients announced in durable storage (oldest first); returns
        real steps stored. Each batch of entries is indexed and trimmed in one transaction."""
        if not getattr(self.storage, "durable", False):
            return 0
        stored = 0
        with self.lock:
            while True:
                entries, consumed, bad = self.storage.read_pending(limit)
                if consumed == 0:
                    return stored
                keys = [k for e in entries for k in e[0]]
                version, episode, steps = (np.concatenate([e[i] for e in entries] or [np.zeros(0, np.int64)])
                                           for i in (1, 2, 3))
                lag = sum(e[4] for e in entries)
                n, discard = len(keys), []
                if n > self.capacity:  # only the newest `capacity` would survive anyway
                    discard, keys = keys[:n - self.capacity], keys[n - self.capacity:]
                    version, episode, steps = (x[n - self.capacity:] for x in (version, episode, steps))
                    self._skip(n - self.capacity)
                if keys:
                    stored += self._place(version, episode, steps, lambda slots, meta: self.storage.register(
                        slots, keys, meta, consumed=consumed, discard=discard, check=False))
                else:
                    self.storage.register(np.zeros(0, np.int64), [], {}, consumed=consumed, discard=discard,
                                          check=False)
                self.counters["drops_policy_lag"] += lag
                self.counters["drops_corrupt"] += bad  # malformed entries (their records become orphans)
                if consumed < limit:
                    return stored

    def _skip(self, n: int) -> None:
        """n windows of one call that would be evicted by the same call."""
        self.counters["drops_evicted"] += n
        self.counters["inserts"] += n
        self.count += n

    def _place(self, version: np.ndarray, episode: np.ndarray, steps: np.ndarray, write) -> int:
        n = len(steps)
        if n == 0:
            return 0
        ids = self.count + np.arange(n, dtype=np.int64)  # write ids = stamps
        slots = self._slots_for(ids)
        evicted = int((self.stamp[slots] >= 0).sum())
        prio = np.full(n, self.max_priority)  # new items at the current max priority
        meta = {"stamp": ids, "version": version, "episode": episode, "steps": steps, "priority": prio}
        write(slots, meta)  # durable before the index sees it (raises: nothing changed)
        self.counters["drops_evicted"] += evicted
        self.count += n
        return self._index(slots, ids, version, episode, steps, prio)

    def _index(self, slots: np.ndarray, ids: np.ndarray, version: np.ndarray, episode: np.ndarray,
               steps: np.ndarray, prio: np.ndarray) -> int:
        """Make stored rows `slots` [n] live under write ids `ids` [n] (in write order); returns
        their real steps."""
        self.version[slots], self.episode[slots] = version, episode
        self.steps[slots], self.priority[slots] = steps, prio
        self.born[slots] = self.clock + np.cumsum(steps) - steps  # windows in write order
        self.stamp[slots] = ids  # last: a slot is live only with all its metadata (shm outlives a crash)
        self.clock += int(steps.sum())
        self.tree.set(slots, self._mass(prio))
        self.counters["inserts"] += len(slots)
        return int(steps.sum())

    def _slots_for(self, ids: np.ndarray) -> np.ndarray:
        """Slots of new write ids: a FIFO ring, so the oldest sequence is evicted first."""
        return ids % self.capacity

    # -- sample -------------------------------------------------------------------------
    def mass(self) -> tuple[int, float, int]:
        """(sequences, total sampling mass, real steps) for the client's cross-shard split."""
        self.drain()
        with self.lock:
            return self.size_sequences, self.tree.total, self.size_steps

    def sample(self, k: int, beta: float = 0.0, global_count: int = 0, global_mass: float = 0.0) -> dict:
        """k draws with their rows; `is_weight` = (N P(i))^-beta with the union's N and mass
        (not normalised). Returns {"slots" [k], "stamps" [k], "is_weight" [k], "data"
        {field: [k, T, ...]}, "mask" [k, T] bool}. (A reader that fetches records itself
        uses `draw`.)"""
        if k < 0:
            raise ValueError(f"sample size must be >= 0, got {k}")
        self.drain()
        with self.lock:
            if self.tree.total <= 0:
                raise ValueError(f"replay shard {self.shard_id} is empty")
            slots = self.tree.sample(k, self.rng)
            out: dict = {"data": {f: np.zeros((k, self.T, *s.shape), dtype=s.dtype) for f, s in self.fields.items()},
                         "mask": np.zeros((k, self.T), dtype=bool)}
            todo = np.arange(k)
            while todo.size:
                data, mask, bad = self.storage.read(slots[todo])
                good = np.setdiff1d(np.arange(todo.size), bad)
                for f in out["data"]:
                    out["data"][f][todo[good]] = data[f][good]
                out["mask"][todo[good]] = mask[good]
                if bad.size:  # unreadable in storage: forget the slot, count it, draw again
                    self._drop(np.unique(slots[todo[bad]]))
                    if self.tree.total <= 0:
                        raise ValueError(f"replay shard {self.shard_id} is empty")
                    slots[todo[bad]] = self.tree.sample(bad.size, self.rng)
                todo = todo[bad]
            w = is_weights(self.tree.get(slots), global_count or self.size_sequences,
                           global_mass or self.tree.total, beta if self.prioritized else 0.0)
            self.counters["samples"] += k
            out.update(is_weight=w.astype(np.float32), slots=slots, stamps=self.stamp[slots].copy(),
                       newer=self.newer(slots))
            return out

    def draw(self, k: int) -> dict:
        """k draws for a reader that fetches the records itself -> {"slots", "stamps", "keys",
        "mass" [k] (each draw's sampling mass, for IS weights), "size" (sequences), "total"
        (sampling mass)}; an empty shard returns no draws (and total 0) instead of raising."""
        if k < 0:
            raise ValueError(f"draw size must be >= 0, got {k}")
        self.drain()
        with self.lock:
            total, size = self.tree.total, self.size_sequences
            slots = self.tree.sample(k, self.rng) if total > 0 and k > 0 else np.zeros(0, np.int64)
            self.counters["samples"] += slots.size
            keys = self.storage.key_of(slots) if self.storage.durable else []  # memory: nothing to fetch by key
            return {"slots": slots, "stamps": self.stamp[slots].copy(), "keys": keys,
                    "mass": self.tree.get(slots), "size": size, "total": total, "newer": self.newer(slots)}

    def _drop(self, slots: np.ndarray) -> None:
        self.counters["drops_corrupt"] += slots.size
        self.stamp[slots] = -1
        self.tree.set(slots, np.zeros(slots.size))
        self.storage.drop(slots)

    def drop_corrupt(self, slots: np.ndarray, stamps: np.ndarray) -> int:
        """A reader found these records undecodable: forget them (if unchanged since drawn)."""
        with self.lock:
            slots = np.asarray(slots, np.int64)
            ok = (self.stamp[slots] == np.asarray(stamps, np.int64)) & (self.stamp[slots] >= 0)
            dead = np.unique(slots[ok])
            if dead.size:
                self._drop(dead)
            return int(dead.size)

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
        self.drain()
        with self.lock:
            index = sum(getattr(self, k).nbytes for k in self._INDEX) + self.tree.tree.nbytes
            return {"size_steps": float(self.size_steps), "size_sequences": float(self.size_sequences),
                    "capacity_sequences": float(self.capacity),
                    "bytes": float(self.storage.nbytes + index), **{k: float(v) for k, v in self.counters.items()}}

    _INDEX = ("stamp", "version", "episode", "steps", "priority")

    def save(self, path: str) -> None:
        """Write index, priorities, counters and (memory storage) the arrays to `path` (.npz)."""
        self.drain()
        with self.lock:
            arrays = {"i_" + k: getattr(self, k) for k in self._INDEX}
            if not self.storage.durable:
                # rows from the last live slot on were never written (the ring fills from slot 0): a
                # young run's checkpoint holds what it stored, not the zeros of a 100k-step buffer
                live = np.flatnonzero(self.stamp >= 0)
                n = int(live[-1]) + 1 if live.size else 0
                arrays.update({k: a[:n] for k, a in self.storage.arrays().items()})  # views: no copy
            scalars = {"count": self._saved_count(), "max_priority": self.max_priority, "counters": self.counters,
                       "capacity": self.capacity, "seq_len": self.T}
            arrays["scalars"] = np.frombuffer(json.dumps(scalars).encode(), dtype=np.uint8)
            tmp = path + ".tmp.npz"
            np.savez(tmp, **arrays)
            os.replace(tmp, path)

    def _saved_count(self) -> int:
        return self.count

    def restore(self, path: str) -> None:
        """Load what `save` wrote (never unpickles). Durable storage re-reads redis instead."""
        with self.lock, np.load(path, allow_pickle=False) as z:
            scalars = _scalars(z)
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
            self._rebuild_clock()

    def close(self) -> None:
        self.storage.close()


def _scalars(z: Any) -> dict:
    """The JSON scalars `ReplayShard.save` stores beside the arrays of an open .npz."""
    return json.loads(bytes(z["scalars"]).decode())


def saved_layout(path: str | os.PathLike) -> tuple[int, int]:
    """(capacity in sequence slots, seq_len) of a shard file `save` wrote, read without its arrays."""
    with np.load(path, allow_pickle=False) as z:
        scalars = _scalars(z)
    return int(scalars["capacity"]), int(scalars["seq_len"])
