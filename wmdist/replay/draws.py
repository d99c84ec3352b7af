"""DrawPool / DrawPools: a client's stock of each shard's draws, taken ahead of the sample that uses them.

A reader that fetches records from redis itself needs only (slot, stamp, key, mass) per
draw from the shard. Asking the shard for the next batch's draws while the current batch
is being fetched takes the shard round trip off the sample's critical path. Draws are
i.i.d., so taking any k of them from the stock is a valid sample of k. They are at most a
call or two old: a drawn record evicted since is simply missing at fetch time and drawn
again, and the stamp drawn with it keeps write-backs exact (a record key is never reused).
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np


class DrawPool:
    """One shard's draws not yet taken: arrays [n] whose first `head` entries are spent (a
    take moves `head` and returns views, so it costs O(k), not a copy of the whole stock)."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.slots = np.zeros(0, np.int64)  # [n]
        self.stamps = np.zeros(0, np.int64)  # [n]
        self.mass = np.zeros(0, np.float64)  # [n] sampling mass of each draw when drawn
        self.newer = np.zeros(0, np.int64)  # [n] real steps its shard placed after the draw's window
        self.keys: list[str] = []  # [n] record keys
        self.born = np.zeros(0, np.float64)  # [n] when each draw arrived (monotonic seconds)
        self.head = 0  # draws [0, head) are spent
        self.size = 0  # the shard's sequences at its latest report
        self.total = 0.0  # the shard's sampling mass at its latest report
        self.reported_at = -math.inf  # when the request that brought that report was sent

    @property
    def reported(self) -> bool:
        return self.reported_at > -math.inf

    def __len__(self) -> int:
        return self.slots.size - self.head

    def add(self, draw: dict, now: float = 0.0) -> None:
        """Append a `ReplayShard.draw` result asked for at `now`; its size and mass become
        the latest report."""
        h, k = self.head, len(draw["slots"])
        self.born = np.concatenate([self.born[h:], np.full(k, now)])
        self.slots = np.concatenate([self.slots[h:], np.asarray(draw["slots"], np.int64)])
        self.stamps = np.concatenate([self.stamps[h:], np.asarray(draw["stamps"], np.int64)])
        self.mass = np.concatenate([self.mass[h:], np.asarray(draw["mass"], np.float64)])
        newer = draw.get("newer")
        self.newer = np.concatenate([self.newer[h:], np.zeros(k, np.int64) if newer is None
                                     else np.asarray(newer, np.int64)])
        self.keys = self.keys[h:] + list(draw["keys"])
        self.head = 0
        self.size, self.total, self.reported_at = int(draw["size"]), float(draw["total"]), now

    def expire(self, before: float) -> None:
        """Drop draws that arrived before `before` (a slow reader should not see old draws)."""
        if self.head < self.born.size and self.born[self.head] < before:  # arrival times never decrease
            self.head = int(np.searchsorted(self.born, before))

    def take(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str], np.ndarray]:
        """The oldest k draws -> (slots, stamps, mass, keys, newer); they leave the pool."""
        if k > len(self):
            raise ValueError(f"draw pool holds {len(self)} draws, {k} asked")
        a, b = self.head, self.head + k
        self.head = b
        return self.slots[a:b], self.stamps[a:b], self.mass[a:b], self.keys[a:b], self.newer[a:b]


def is_weights(mass: np.ndarray, size: int, total: float, beta: float) -> np.ndarray:
    """w_i = (N P(i))^-beta with P(i) = mass_i / total over the union of shards (Schaul et
    al. 2016, Sec. 3.4); not normalised. beta = 0 (uniform) gives ones."""
    if beta <= 0 or total <= 0:
        return np.ones(len(mass), np.float64)
    return np.power(size * np.asarray(mass, np.float64) / total, -beta)


class DrawPools:
    """One reader's `DrawPool` per shard and the draw requests in flight for them.

    Ray-free: `send(shard, k)` starts a request for k draws and returns a handle, `fetch(handles)`
    blocks for their results (`ReplayShard.draw` dicts). `take(B)` is served from the pools;
    a shard call sits on its path only when a pool runs short, and then it is usually the
    request sent ahead, back long since. With `prefetch`, a pool below `S * ahead * B * share`
    draws (share: the shard's part of the union's mass) gets one request for that many, so
    each shard is called about once per `S * ahead` takes, at least `ahead` takes before its
    draws are needed, and the union about once per `ahead` takes however many shards it has
    (a shard call costs the reader ~0.1 ms, as much as the rest of a vector sample); the
    other shards' pools below twice that are asked at the same time, and a fetch reads
    every request sent with the one it waits for (one fetch per refill, not S).
    Draws count as born when their request was sent; older than `max_age` they are dropped
    (so a slow reader sees fresh contents)."""

    def __init__(self, shards: int, send: Callable[[int, int], Any], fetch: Callable[[list], list],
                 ahead: int = 16, max_age: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.pools = [DrawPool() for _ in range(shards)]
        self.send, self.fetch, self.ahead, self.max_age, self.clock = send, fetch, ahead, max_age, clock
        self.inflight: dict[int, tuple[float, Any]] = {}  # shard -> (sent at, handle)
        self.fetches = 0  # fetch calls a take had to make (each may wait for a shard)

    def clear(self) -> None:
        """Forget every draw and request (after a write of this reader: they may not reflect it)."""
        for p in self.pools:
            p.clear()
        self.inflight.clear()

    def take(self, B: int, rng: np.random.Generator, prefetch: bool = True, ahead: int | None = None):
        """B draws split over shards by their latest size / mass reports -> (shard_of, slots,
        stamps, mass, keys, union size, union mass, newer) with arrays [B], or None if every
        shard is empty. `ahead`: takes of this size to ask ahead for (default: the pools')."""
        pools, S = self.pools, len(self.pools)
        now = self.clock()
        for p in pools:
            p.expire(now - self.max_age)
        # no report yet, or an empty pool with an old one (a shard empty then may hold data now)
        self._fill([s for s, p in enumerate(pools) if now - p.reported_at >= self.max_age and not len(p)], B)
        if sum(p.total for p in pools) <= 0:  # maybe an old report: ask every shard afresh
            self.clear()
            self._fill(range(S), B, fresh=True)
            if sum(p.total for p in pools) <= 0:
                return None
        for _ in range(100):
            totals = [p.total for p in pools]
            total = float(sum(totals))
            counts = [B] if S == 1 else rng.multinomial(B, np.array(totals) / total).tolist()
            short = [s for s in range(S) if len(pools[s]) < counts[s]]
            if not short:
                break
            self._fill(short, B)
            if sum(p.total for p in pools) <= 0:
                return None
        else:
            raise RuntimeError("replay: shards kept returning too few draws")
        n = sum(p.size for p in pools)
        taken = [(s, pools[s].take(k)) for s, k in enumerate(counts) if k > 0]
        if prefetch:  # read back by a later take, so it is there in time
            ahead = self.ahead if ahead is None else ahead
            want = [max(B, math.ceil(S * ahead * B * p.total / total)) for p in pools]
            if any(len(p) < w and s not in self.inflight for s, (p, w) in enumerate(zip(pools, want))):
                # one pool runs low: every shard not asked yet and below twice its share is asked
                # now too, so their answers come back together and one fetch reads them all
                for s, (p, w) in enumerate(zip(pools, want)):
                    if len(p) < 2 * w and s not in self.inflight:
                        self.inflight[s] = (now, self.send(s, w))
        if len(taken) == 1:  # one shard: its arrays as they are
            s, (slots, stamps, mass, keys, newer) = taken[0]
            return np.full(B, s, np.int64), slots, stamps, mass, keys, n, total, newer
        shard_of = np.repeat(np.array([s for s, _ in taken], np.int64), [len(t[0]) for _, t in taken])
        slots, stamps, mass, newer = (np.concatenate([t[i] for _, t in taken]) for i in (0, 1, 2, 4))
        return shard_of, slots, stamps, mass, [k for _, t in taken for k in t[3]], n, total, newer

    def _fill(self, shards, k: int, fresh: bool = False) -> None:
        """Add each shard's request in flight to its pool (waiting for it), or, with `fresh`,
        none in flight or one too old to use, k new draws."""
        shards = list(shards)
        if not shards:
            return
        if not fresh:  # requests sent with theirs or before are as likely back: read them in the same fetch
            sent = [self.inflight[s][0] for s in shards if s in self.inflight]
            shards += [s for s, (t, _) in self.inflight.items() if sent and s not in shards and t <= max(sent)]
        now, reqs = self.clock(), {}
        for s in shards:
            sent, handle = self.inflight.pop(s, (0.0, None))
            if handle is None or fresh or now - sent >= self.max_age:
                sent, handle = now, self.send(s, k)
            reqs[s] = (sent, handle)
        self.fetches += 1
        for (s, (sent, _)), d in zip(reqs.items(), self.fetch([h for _, h in reqs.values()])):
            self.pools[s].add(d, sent)
