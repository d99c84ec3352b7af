"""GatheredStock: the rows of several samples gathered at once, served back-to-back as views.

A drawn sample (shared memory or redis) pays fixed costs on every call, and again for every
shard: splitting the draws over the shards, one gather per shard (a seqlock read or an
MGET), the Python around them. A reader that samples back-to-back (a fast learner, the
bench) can take k batches' draws and rows in one go and serve the next k samples as slices
of them, so those costs are spread over k samples and S shards cost about what one does.

Draws are i.i.d., so any B rows of the stock are a valid sample of B; the next sample's
rows are simply drawn a little earlier. Four bounds keep that harmless (`batches_ahead`):
- a stock is gathered only when the reader did not write since its previous sample (its
  writes must show in what it samples next: a learner that updates priorities every step
  never gets one), and it is dropped at the reader's next write;
- it covers at most as many samples as the reader took in the last `HORIZON` seconds, so a
  slow reader (a learner whose update takes 100 ms) gathers two or three batches at a time
  and a reader that stops leaves little unused;
- it holds at most `BUDGET_BYTES` of rows (pixel batches: one at a time);
- it is dropped once older than the draws' own age limit.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

MAX_BATCHES = 32  # samples one gather serves at most (the default of `replay.sample_ahead`)
BUDGET_BYTES = 8 << 20  # rows one stock holds at most
HORIZON = 0.25  # seconds of the reader's recent pace one stock covers at most


class Pace:
    """How many sample calls a reader made in the last `HORIZON` seconds (counted up to
    `MAX_BATCHES`): what it will likely take in the next ones. A count, not an average
    interval, so a reader that samples in bursts (a block of calls, then other work) is
    judged by the burst."""

    def __init__(self, horizon: float = HORIZON, most: int = MAX_BATCHES) -> None:
        self.horizon = horizon
        self.calls: deque[float] = deque(maxlen=most)

    def tick(self, now: float) -> int:
        """Record a call at `now`; returns the calls in (now - horizon, now], this one included."""
        self.calls.append(now)
        while self.calls[0] <= now - self.horizon:
            self.calls.popleft()
        return len(self.calls)


def batches_ahead(recent_calls: int, batch_bytes: int, max_batches: int = MAX_BATCHES,
                  budget: int = BUDGET_BYTES) -> int:
    """Batches one gather should cover: the reader's calls of the last `HORIZON` seconds,
    within `budget` bytes and `max_batches`; at least 1."""
    return int(max(1, min(max_batches, recent_calls, budget // max(batch_bytes, 1))))


@dataclass
class GatheredStock:
    """k batches of B gathered rows ([k*B] arrays; `head` rows already served) and what they
    were drawn from: union size `n` and mass `total` (for IS weights), this reader's write
    count `gen` and the time `born` the draws were asked for."""

    data: dict[str, np.ndarray]  # field -> [k*B, T, ...]
    mask: np.ndarray  # [k*B, T] float32
    age: np.ndarray  # [k*B, T] int64
    shard_of: np.ndarray  # [k*B]
    slots: np.ndarray  # [k*B]
    stamps: np.ndarray  # [k*B]
    mass: np.ndarray  # [k*B] sampling mass of each draw
    n: int
    total: float
    batch: int  # B
    gen: int
    born: float
    head: int = 0

    def left(self) -> int:
        return len(self.slots) - self.head

    def serves(self, batch: int, gen: int, now: float, max_age: float) -> bool:
        """Can the next sample of `batch` come from here: same batch size, no write by the
        reader since the gather, not too old, rows left?"""
        return batch == self.batch and gen == self.gen and now - self.born < max_age and self.left() >= batch

    def take(self, batch: int) -> slice:
        """The rows of the next `batch` draws (slice them: views, no copy); they leave the stock."""
        if batch > self.left():
            raise ValueError(f"stock holds {self.left()} rows, {batch} asked")
        self.head += batch
        return slice(self.head - batch, self.head)
