"""Rate limiter: keeps sampled sequences per inserted sequence near `samples_per_insert`.

Counting starts once `min_size` real steps are stored (before that inserts pass freely and
samples wait). With I sequences inserted and S sampled since then, the signed error
`e = S - I * spi` is kept inside the band `[-error_buffer, +error_buffer]`:

- a sample of B waits while `e > error_buffer` (the learner is ahead of the collectors),
- an insert of n waits while `e < -error_buffer` (the collectors are ahead).

Each check is made before the call is granted, so a granted call overshoots the band by at
most its own size: `e` stays in `[-error_buffer - n_max*spi, error_buffer + B_max]`. Both
conditions can't hold at once, so inserts and samples never wait on each other forever;
`close()` wakes every waiter (they return False). `spi = 0` disables the ratio (only
`min_size` holds samples back). Thread-safe; no Ray.
"""
from __future__ import annotations

import threading
import time
from typing import Any


class RateLimiter:
    def __init__(self, samples_per_insert: float, min_size: int, error_buffer: float) -> None:
        if samples_per_insert < 0 or min_size < 0 or error_buffer < 0:
            raise ValueError("rate limiter: samples_per_insert, min_size and error_buffer must be >= 0")
        self.spi = float(samples_per_insert)
        self.min_size = int(min_size)
        self.error_buffer = float(error_buffer)
        self._cv = threading.Condition()
        self._closed = False
        self.size_steps = 0  # real steps stored (committed by the shards' acks)
        self.inserted = 0  # sequences granted since min_size was reached
        self.sampled = 0  # sequences sampled since min_size was reached
        self.total_inserted = 0
        self.total_sampled = 0
        self.insert_wait_seconds = 0.0
        self.sample_wait_seconds = 0.0

    # -- conditions ---------------------------------------------------------------------
    def _ready(self) -> bool:
        return self.size_steps >= self.min_size

    def _error(self) -> float:
        return self.sampled - self.inserted * self.spi

    def _can_insert(self) -> bool:
        return self.spi == 0 or not self._ready() or self._error() >= -self.error_buffer

    def _can_sample(self) -> bool:
        return self._ready() and (self.spi == 0 or self._error() <= self.error_buffer)

    def _wait(self, cond, timeout: float | None) -> tuple[bool, float]:
        t0 = time.monotonic()
        deadline = None if timeout is None else t0 + timeout
        while not self._closed and not cond():
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                break
            self._cv.wait(left)
        return (not self._closed and cond()), time.monotonic() - t0

    # -- calls --------------------------------------------------------------------------
    def acquire_insert(self, n_sequences: int, timeout: float | None = None) -> bool:
        """Wait (up to timeout) until n sequences may be inserted; False on timeout or close."""
        with self._cv:
            ok, waited = self._wait(self._can_insert, timeout)
            self.insert_wait_seconds += waited
            if ok:
                self.total_inserted += n_sequences
                if self._ready():
                    self.inserted += n_sequences
                self._cv.notify_all()
            return ok

    def commit_insert(self, n_steps: int) -> None:
        """The shards stored n_steps more real steps (may satisfy min_size)."""
        with self._cv:
            self.size_steps += int(n_steps)
            self._cv.notify_all()

    def set_size(self, size_steps: int) -> None:
        """Resync the stored size (after eviction or a restore)."""
        with self._cv:
            self.size_steps = int(size_steps)
            self._cv.notify_all()

    def acquire_sample(self, n_sequences: int, timeout: float | None = None) -> bool:
        """Wait (up to timeout) until n sequences may be sampled; False on timeout or close."""
        with self._cv:
            ok, waited = self._wait(self._can_sample, timeout)
            self.sample_wait_seconds += waited
            if ok:
                self.sampled += n_sequences
                self.total_sampled += n_sequences
                self._cv.notify_all()
            return ok

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed

    # -- checkpoint ---------------------------------------------------------------------
    _STATE = ("size_steps", "inserted", "sampled", "total_inserted", "total_sampled",
              "insert_wait_seconds", "sample_wait_seconds")

    def state_dict(self) -> dict[str, Any]:
        with self._cv:
            return {k: getattr(self, k) for k in self._STATE}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        missing = [k for k in self._STATE if k not in state]
        if missing:
            raise ValueError(f"rate limiter state is missing '{missing[0]}'")
        with self._cv:
            for k in self._STATE:
                setattr(self, k, type(getattr(self, k))(state[k]))
            self._cv.notify_all()

    def stats(self) -> dict[str, float]:
        with self._cv:
            return {
                "limiter_size_steps": float(self.size_steps),
                "limiter_inserted": float(self.total_inserted),
                "limiter_sampled": float(self.total_sampled),
                "limiter_error": float(self._error()),
                "insert_wait_seconds": self.insert_wait_seconds,
                "sample_wait_seconds": self.sample_wait_seconds,
            }
