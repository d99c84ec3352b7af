"""ShmPath: a replay client's direct access to its shards' shared-memory segments.

Built once per process that holds a client (`connect`), only when every shard keeps its
rows in shared memory (`ShmShard`) on this process's Ray node; otherwise the client moves
rows through actor calls as before. Insert: rows written into slots reserved ahead and
committed in the segment (`shm_rows.commit_rows`; the shard indexes them on its next
read), with no shard call on the path while the stock of reserved slots lasts: the next
ones are asked for while four inserts' worth remain, so the answer is back in time.
Sample: the client's draws (the draw pools of the redis path) gathered straight from the
segments (`shm_rows.read_rows`); a row rewritten since its draw is drawn again through the
caller's `redraw`.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.reservations import Reservations
from wmdist.replay.shard_shm import LEASE_USE_SECONDS
from wmdist.replay.shm import H_CLOSED, ShmSegment, ShmUnavailable
from wmdist.replay.shm_rows import ShmRows, commit_rows, read_rows, write_rows
from wmdist.runtime.calls import get, is_local

AHEAD_SHARE = 16  # a client reserves ahead at most 1/16 of a shard's slots (its last insert's share)


class StaleSegment(RuntimeError):
    """A shard now uses another segment than the one this client mapped (it was recreated)."""


def node_id() -> str:
    import ray

    return ray.get_runtime_context().get_node_id()


class ShmPath:
    def __init__(self, shards: list, segs: list[ShmSegment], capacity: int) -> None:
        self.shards, self.segs = shards, segs
        self.res = [Reservations() for _ in shards]
        self.inflight: dict[int, tuple[float, object]] = {}  # shard -> (sent at, reserve request)
        self.last = [0] * len(shards)  # rows of the latest insert into each shard
        self.ahead = capacity // AHEAD_SHARE
        self.broken = False  # a shard answered for another segment: the client reconnects
        self.rows: ShmRows | None = None  # the segments' row sources, made at the first read

    @classmethod
    def connect(cls, shards: list, fields: dict[str, FieldSpec], seq_len: int, capacity: int) -> "ShmPath | None":
        """Map every shard's segment, or None (a shard without one, on another node, or no
        shared memory here)."""
        if not shards or any(is_local(s) for s in shards):
            return None
        infos = get([s.shm_info.remote() for s in shards])
        if any(i is None for i in infos) or any(i["node"] != node_id() for i in infos):
            return None
        segs: list[ShmSegment] = []
        try:
            for i in infos:
                segs.append(ShmSegment.attach(i["name"], fields, capacity, seq_len, i["token"]))
        except (OSError, ShmUnavailable):
            for s in segs:
                s.close()
            return None
        return cls(shards, segs, capacity)

    def close(self) -> None:
        self.rows = None  # its views first, so the mappings can close
        for s in self.segs:
            s.close()
        self.segs = []

    @property
    def closed(self) -> bool:
        """A shard closed its segment (the service was shut down)."""
        return any(int(s.header[H_CLOSED]) for s in self.segs)

    # -- insert -------------------------------------------------------------------------
    def insert(self, batch: SequenceBatch, dest: np.ndarray, keep: np.ndarray, steps: np.ndarray) -> int:
        """Rows `keep` of `batch` [N] into shards `dest` [N] (`steps` [N] real steps each);
        the others are counted as policy-lag drops. Acknowledged on return: committed in the
        segments (or, past the reserved slots, stored by an actor call). Returns the real
        steps stored."""
        now = time.monotonic()
        parts = []  # (shard, rows, policy-lag drops)
        for s in np.unique(dest):
            rows = np.flatnonzero((dest == s) & keep)
            lag = int(((dest == s) & ~keep).sum())
            if rows.size or lag:
                parts.append((int(s), rows, lag))
        for r in self.res:
            r.expire(now - LEASE_USE_SECONDS)
        short = [(s, rows.size) for s, rows, _ in parts if rows.size > len(self.res[s])]
        if short:  # the stock runs short: the request in flight, else one now (waited for)
            for s, n in short:
                if s not in self.inflight:
                    self.inflight[s] = (now, self.shards[s].reserve.remote(n - len(self.res[s]) + self._target(s)))
            self._receive([s for s, _ in short])
        stored, calls = 0, []
        for s, rows, lag in parts:
            slots, stamps = self.res[s].take(rows.size)
            mine, rest = rows[:slots.size], rows[slots.size:]
            if slots.size:
                whole = mine.size == len(batch)  # rows are ascending: all of the batch, in order
                write_rows(self.segs[s], slots, batch, None if whole else mine)
                commit_rows(self.segs[s], slots, stamps, batch.version[mine], batch.episode_id[mine], steps[mine])
                stored += int(steps[mine].sum())
            if rest.size:  # no slot reserved for these (the ring is short of unreserved slots): by call
                calls.append(self.shards[s].insert.remote(batch.select(rest), None))
            if lag:
                calls.append(self.shards[s].count_lag.remote(lag))
            self.last[s] = max(int(rows.size), 1)
        stored += sum(int(x or 0) for x in get(calls))
        self._prefetch(now)
        return stored

    def _target(self, s: int) -> int:
        """Slots to hold for shard s: 8 inserts' worth, at most 1/AHEAD_SHARE of it."""
        return min(self.ahead, 8 * self.last[s])

    def _prefetch(self, now: float) -> None:
        """Ask ahead (not waited for) where the stock would not cover four more inserts: the
        answer of a loaded shard can take several back-to-back inserts' time."""
        for s, r in enumerate(self.res):
            if self.last[s] and s not in self.inflight and len(r) < 4 * self.last[s]:
                want = self._target(s) - len(r)
                if want > 0:
                    self.inflight[s] = (now, self.shards[s].reserve.remote(want))

    def _receive(self, shards: list[int]) -> None:
        """Add the answers of these shards' reserve requests (waiting for them)."""
        sent = [self.inflight.pop(s) for s in shards]
        for s, (at, _), got in zip(shards, sent, get([h for _, h in sent])):
            if got["seg"] == self.segs[s].token:
                self.res[s].add(got, at)
            else:  # reserved in a segment this client did not map: those rows go by call
                self.broken = True

    # -- sample -------------------------------------------------------------------------
    def gather(self, fields: dict[str, FieldSpec], seq_len: int, shard_of: np.ndarray, slots: np.ndarray,
               stamps: np.ndarray, redraw: Callable[[int, np.ndarray], None]
               ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """The drawn rows, from any shards in any order -> (fields [B, T, ...], mask [B, T]
        bool). Rows found rewritten are drawn again by `redraw(shard, rows)`, which replaces
        `slots` and `stamps` at `rows`."""
        B = len(slots)
        data = {f: np.empty((B, seq_len, *s.shape), np.dtype(s.dtype)) for f, s in fields.items()}
        mask = np.empty((B, seq_len), bool)
        if self.rows is None or self.rows.fields != list(fields):
            self.rows = ShmRows(self.segs, list(fields))
        todo = read_rows(self.rows, shard_of, slots, stamps, data, mask)
        for _ in range(100):
            if todo.size == 0:
                return data, mask
            for s in np.unique(shard_of[todo]):
                redraw(int(s), todo[shard_of[todo] == s])
            todo = todo[read_rows(self.rows, shard_of[todo], slots[todo], stamps[todo], data, mask, at=todo)]
        raise RuntimeError("replay: rows kept changing under 100 reads (shards rewriting faster than reads)")
