"""DrawPool: a client's stock of one shard's draws, taken ahead of the sample that uses them.

A reader that fetches records from redis itself needs only (slot, stamp, key, mass) per
draw from the shard. Asking the shard for the next batch's draws while the current batch
is being fetched takes the shard round trip off the sample's critical path. Draws are
i.i.d., so taking any k of them from the stock is a valid sample of k. They are at most a
call or two old: a drawn record evicted since is simply missing at fetch time and drawn
again, and the stamp drawn with it keeps write-backs exact (a record key is never reused).
"""
from __future__ import annotations

import numpy as np


class DrawPool:
    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.slots = np.zeros(0, np.int64)  # [n]
        self.stamps = np.zeros(0, np.int64)  # [n]
        self.mass = np.zeros(0, np.float64)  # [n] sampling mass of each draw when drawn
        self.keys: list[str] = []  # [n] record keys
        self.born = np.zeros(0, np.float64)  # [n] when each draw arrived (monotonic seconds)
        self.size = 0  # the shard's sequences at its latest report
        self.total = 0.0  # the shard's sampling mass at its latest report
        self.reported = False

    def __len__(self) -> int:
        return int(self.slots.size)

    def add(self, draw: dict, now: float = 0.0) -> None:
        """Append a `ReplayShard.draw` result that arrived at `now`; its size and mass become
        the latest report."""
        self.born = np.concatenate([self.born, np.full(len(draw["slots"]), now)])
        self.slots = np.concatenate([self.slots, np.asarray(draw["slots"], np.int64)])
        self.stamps = np.concatenate([self.stamps, np.asarray(draw["stamps"], np.int64)])
        self.mass = np.concatenate([self.mass, np.asarray(draw["mass"], np.float64)])
        self.keys += list(draw["keys"])
        self.size, self.total, self.reported = int(draw["size"]), float(draw["total"]), True

    def expire(self, before: float) -> None:
        """Drop draws that arrived before `before` (a slow reader should not see old draws)."""
        n = int(np.searchsorted(self.born, before))  # arrival times are non-decreasing
        if n:
            self.take(n)

    def take(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
        """The oldest k draws -> (slots, stamps, mass, keys); they leave the pool."""
        if k > len(self):
            raise ValueError(f"draw pool holds {len(self)} draws, {k} asked")
        out = self.slots[:k], self.stamps[:k], self.mass[:k], self.keys[:k]
        self.slots, self.stamps, self.mass, self.keys = self.slots[k:], self.stamps[k:], self.mass[k:], self.keys[k:]
        self.born = self.born[k:]
        return out


def is_weights(mass: np.ndarray, size: int, total: float, beta: float) -> np.ndarray:
    """w_i = (N P(i))^-beta with P(i) = mass_i / total over the union of shards (Schaul et
    al. 2016, Sec. 3.4); not normalised. beta = 0 (uniform) gives ones."""
    if beta <= 0 or total <= 0:
        return np.ones(len(mass), np.float64)
    return np.power(size * np.asarray(mass, np.float64) / total, -beta)
