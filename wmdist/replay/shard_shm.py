"""ShmShard: a `ReplayShard` whose rows, index and counters live in a shared-memory segment.

Everything the shard knows is in its segment (`shm.ShmSegment`), so a shard actor killed
by SIGKILL and restarted by Ray re-attaches it by name and rebuilds only its sum tree:
it loses no acknowledged sequence. Readers on the shard's node copy rows out of the
segment themselves (`shm_rows.read_rows`), checking each slot's stamp and generation.

Inserts with no actor call on their path: a client `reserve`s slots ahead of time (each
gets its write id = stamp; its old row leaves the index now), writes rows into them, then
commits each in the segment itself: its commit record (version, episode, steps), then
`commit[slot]` = its write id. That is the acknowledgement: the shard indexes committed
slots on its next read (`drain`, like the redis path's pending entries), and a restarted
shard at once, so a shard killed in between loses nothing acknowledged. Only committed
rows are ever indexed, so a reservation whose client died is a hole until the ring comes
round to it again. A reservation is a lease: after `LEASE_SECONDS` its slot may be handed
out again (a late commit of it is then ignored); clients use a reservation for
`LEASE_USE_SECONDS` at most, so a late writer never meets a new one. Outstanding
reservations hold at most 1/`RESERVE_SHARE` of the slots, so the ring always has room for
the shard's own (actor-call) inserts.

Crash order: a slot is live iff its stamp is >= 0, and the stamp is written after the rest
of its metadata; a row written by the shard has an odd `gen` while being written, and is
dropped (counted corrupt) if the shard died right then.
"""
from __future__ import annotations

import time

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.shard import DROP_REASONS, ReplayShard
from wmdist.replay.shm import H_CLOCK, H_COUNT, H_HEAD, H_IBASE, H_IFIRST, H_IFLIGHT, H_STALE, ShmSegment
from wmdist.replay.storage_shm import ShmStorage
from wmdist.replay.sumtree import SumTree

COUNTERS = ("inserts", "samples", *(f"drops_{r}" for r in DROP_REASONS))
LEASE_SECONDS = 120.0
LEASE_USE_SECONDS = 30.0
RESERVE_SHARE = 4


class ShmCounters(dict):
    """The shard's counters dict, every write mirrored into the segment."""

    def __init__(self, array: np.ndarray, names: tuple[str, ...]) -> None:
        self._array, self._at = array, {n: i for i, n in enumerate(names)}
        super().__init__({n: int(array[i]) for n, i in self._at.items()})

    def __setitem__(self, key: str, value: int) -> None:
        super().__setitem__(key, value)
        if key in self._at:
            self._array[self._at[key]] = int(value)

    def update(self, other=(), **kw) -> None:  # type: ignore[override]
        for k, v in dict(other, **kw).items():
            self[k] = v


class _Header:
    """A scalar of the shard kept in the segment's header (int64, or float64 in `fheader`)."""

    def __init__(self, index: int, floating: bool = False) -> None:
        self.i, self.floating = index, floating

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        return float(obj.seg.fheader[self.i]) if self.floating else int(obj.seg.header[self.i])

    def __set__(self, obj, value) -> None:
        if self.floating:
            obj.seg.fheader[self.i] = float(value)
        else:
            obj.seg.header[self.i] = int(value)


class ShmShard(ReplayShard):
    count = _Header(H_COUNT)  # next write id
    clock = _Header(H_CLOCK)
    head = _Header(H_HEAD)  # next slot of the ring to hand out
    max_priority = _Header(0, floating=True)
    # rows a reader found rewritten between its draw and its copy (drawn again): a statistic
    # of the readers, not shard state, so it stays out of checkpoints
    stale_reads = _Header(H_STALE)

    def __init__(self, fields: dict[str, FieldSpec], seq_len: int, capacity: int, segment: ShmSegment,
                 sampler: str = "uniform", alpha: float = 0.6, seed: int = 0, shard_id: int = 0) -> None:
        self.seg = segment
        saved = segment.header.copy(), segment.fheader.copy()
        super().__init__(fields, seq_len, capacity, sampler, alpha, ShmStorage(segment), seed, shard_id)
        segment.header[:], segment.fheader[:] = saved  # the base __init__ reset count, clock, max_priority
        m = segment.meta  # each [C]
        self.stamp, self.version, self.episode, self.steps = m["stamp"], m["version"], m["episode"], m["steps"]
        self.priority, self.born, self.lease, self.lease_t = m["priority"], m["born"], m["lease"], m["lease_t"]
        self.gen, self.commit = m["gen"], m["commit"]  # commit: the write id a client committed a slot under
        self.c_version, self.c_episode, self.c_steps = m["c_version"], m["c_episode"], m["c_steps"]
        self.counters = ShmCounters(segment.counters, COUNTERS)
        if segment.fresh:
            self.stamp[:] = -1
            self.lease[:] = -1
            self.commit[:] = -1
            self.max_priority = 1.0
        else:
            self._reattach()

    def _reattach(self) -> None:
        """A restarted shard: drop rows a write was tearing, then rebuild the sum tree."""
        torn = self.gen % 2 == 1  # [C]
        self.counters["drops_corrupt"] += int((torn & (self.stamp >= 0)).sum())
        self.stamp[torn] = -1
        self.gen[torn] += 1
        self._finish_indexing()
        live = np.flatnonzero(self.stamp >= 0)
        # a commit cut short after its stamps but before the header: counts cover what is there
        self.count = max(self.count, int(max(self.stamp.max(initial=-1), self.lease.max(initial=-1))) + 1)
        self.clock = max(self.clock, int((self.born[live] + self.steps[live]).max(initial=0)))
        self.tree = SumTree(self.capacity)
        self.tree.set(live, self._mass(self.priority[live]))
        self.drain()  # inserts acknowledged (committed in shared memory) but not indexed yet

    def _finish_indexing(self) -> None:
        """The shard died while making rows live: its inserts counter is set (not added to)
        from the count before that indexing plus the rows it made live, so it is exact
        whether the death came before or after the counter's write."""
        h = self.seg.header
        if not h[H_IFLIGHT]:
            return
        first = int(h[H_IFIRST])
        if first >= 0:  # an actor-call insert: write ids first .. count-1, stamped in one go
            done = (self.stamp >= first) & (self.stamp < self.count)
        else:  # a drain: its rows are live under the lease it has not cleared yet
            done = (self.lease >= 0) & (self.stamp == self.lease)
            self.lease[done] = -1
        self.counters["inserts"] = int(h[H_IBASE]) + int(done.sum())
        h[H_IFLIGHT] = 0

    def _index(self, slots: np.ndarray, ids: np.ndarray, version: np.ndarray, episode: np.ndarray,
               steps: np.ndarray, prio: np.ndarray) -> int:
        """`ReplayShard._index` in a bracket a restarted shard can finish (`_finish_indexing`);
        the caller clears the flag once the rows' own bookkeeping (a drain's leases) is done."""
        h = self.seg.header
        h[H_IBASE] = self.counters["inserts"]
        drained = not slots.size or bool(self.lease[slots[0]] == ids[0])  # a drain's rows keep their lease until it ends
        h[H_IFIRST] = -1 if drained else int(ids[0])
        h[H_IFLIGHT] = 1  # last
        return super()._index(slots, ids, version, episode, steps, prio)

    def shm_info(self) -> dict:
        return {"name": self.seg.name, "token": self.seg.token, "capacity": self.capacity, "seq_len": self.T}

    # -- slots ---------------------------------------------------------------------------
    def _leased(self, now: float) -> np.ndarray:
        """[C] bool: slots reserved by a client that may still commit them."""
        return (self.lease >= 0) & (self.lease_t > now - LEASE_SECONDS)

    def _slots_for(self, ids: np.ndarray) -> np.ndarray:
        """The next len(ids) slots of the ring, skipping those under a live reservation."""
        n, C = len(ids), self.capacity
        self.drain()  # a committed slot must be indexed before its lease can lapse
        blocked = self._leased(time.monotonic())
        order = (self.head + np.arange(C if blocked.any() else n)) % C
        free = order[~blocked[order]][:n]
        if free.size < n:
            raise RuntimeError(f"replay shard {self.shard_id}: {n} slots asked, {free.size} not reserved")
        self.head = (int(free[-1]) + 1) % C
        self.lease[free] = -1  # an expired reservation's late commit is ignored
        return free

    def _place(self, version: np.ndarray, episode: np.ndarray, steps: np.ndarray, write) -> int:
        def guarded(slots: np.ndarray, meta: dict) -> None:
            self.stamp[slots] = -1  # a reader holding a draw of an evicted row rejects it from here on
            write(slots, meta)
        stored = super()._place(version, episode, steps, guarded)
        self.seg.header[H_IFLIGHT] = 0
        return stored

    def insert(self, batch: SequenceBatch, min_version: int | None = None) -> int:
        """The actor-call insert; rows beyond the unreserved slots would be evicted by this
        same call, so they are counted so right away."""
        batch.validate(self.fields, self.T)
        with self.lock:
            self.drain()
            free = self.capacity - int(self._leased(time.monotonic()).sum())
            n = len(batch)
            if n > free:
                self._skip(n - free)
                batch = batch.select(np.arange(n - free, n))
            return super().insert(batch, min_version)

    # -- reservations and commits -------------------------------------------------------
    def reserve(self, k: int) -> dict:
        """Up to k slots for a client to write -> {"slots" [k'], "stamps" [k'], "seg"}; their
        old rows leave the index (counted evicted) now."""
        if k < 0:
            raise ValueError(f"reserve size must be >= 0, got {k}")
        with self.lock:
            self.drain()
            now = time.monotonic()
            k = min(k, max(0, self.capacity // RESERVE_SHARE - int(self._leased(now).sum())))
            ids = self.count + np.arange(k, dtype=np.int64)
            slots = self._slots_for(ids) if k else np.zeros(0, np.int64)
            self.counters["drops_evicted"] += int((self.stamp[slots] >= 0).sum())
            self.stamp[slots] = -1
            self.tree.set(slots, np.zeros(k))
            self.lease_t[slots] = now
            self.lease[slots] = ids  # after its time: a lease is never seen with an old one
            self.count += k
            return {"slots": slots, "stamps": ids, "seg": self.seg.token}

    def drain(self, limit: int = 0) -> int:
        """Index the rows clients committed into their reserved slots (every read does this
        first, and a restarted shard at once); returns real steps stored."""
        with self.lock:
            ready = np.flatnonzero((self.lease >= 0) & (self.commit == self.lease) & (self.stamp != self.lease))
            if not ready.size:
                return 0
            ready = ready[np.argsort(self.lease[ready], kind="stable")]  # in write-id order
            st = self.c_steps[ready]
            bad = (st < 0) | (st > self.T)  # a client's commit record that cannot be right: a hole
            if bad.any():
                self.counters["drops_corrupt"] += int(bad.sum())
                self.lease[ready[bad]] = -1
                ready, st = ready[~bad], st[~bad]
            prio = np.full(ready.size, self.max_priority)  # new items at the current max priority
            # live under the committed write id (indexed once: `stamp != lease` above)
            stored = self._index(ready, self.lease[ready], self.c_version[ready], self.c_episode[ready], st, prio)
            self.lease[ready] = -1
            self.seg.header[H_IFLIGHT] = 0
            return stored

    def count_lag(self, n: int) -> None:
        """Rows a client left out for `max_policy_lag` (counted here like the shard's own)."""
        with self.lock:
            self.counters["drops_policy_lag"] += int(n)

    # -- reads and checkpoints ----------------------------------------------------------
    def draw(self, k: int, stale: int = 0) -> dict:
        """`ReplayShard.draw`, counting `stale` rows the reader found rewritten (these draws
        replace them), and naming the segment they index."""
        with self.lock:
            self.stale_reads += int(stale)
            return {**super().draw(k), "seg": self.seg.token}

    def stats(self) -> dict[str, float]:
        """`ReplayShard.stats`; `bytes` is the whole segment (rows, mask, index, commit
        records) plus the sum tree."""
        return {**super().stats(), "bytes": float(self.seg.layout.size + self.tree.tree.nbytes),
                "stale_reads": float(self.stale_reads)}

    def _saved_count(self) -> int:
        """Write ids reserved ahead by live clients and not used yet do not count as written
        (a checkpoint holds what the memory path would hold; a restored service starts there)."""
        live = self.stamp[self.stamp >= 0]
        ahead = self.lease[self.lease > live.max(initial=-1)]
        return int(ahead.min()) if ahead.size else self.count

    def restore(self, path: str) -> None:
        with self.lock:
            super().restore(path)
            self.lease[:] = -1  # reservations of the service before the checkpoint are void
            self.head = self.count % self.capacity
