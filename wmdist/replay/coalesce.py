"""Coalescer: counts that gate nothing right away, summed and sent at most every `every` seconds.

An insert that needs no permission from the rate limiter (ratio off, no policy lag) and a
sample once `min_size` is reached with the ratio off only have to be counted there (size
for `min_size`, stats). A Ray call costs about a millisecond of the caller's time, a large
part of a small insert or sample, so counts are summed: the first goes at once, later ones
with the first `add` that finds the interval over.

No thread and no timer: sending happens on the caller's own thread, inside its own calls
(a background thread calling into Ray while the owner holds locks or shuts down is what we
avoid). So the owner must `flush()` before anything that reads or waits on the counts (a
blocking limiter call, stats, a checkpoint, close); a count is otherwise held at most until
the owner's next `add` after `every`. Ray-free: `send(*totals)` does the sending and returns
a handle; `wait(handles)` blocks until they were applied. The receiver may run calls out of order
(a threaded actor), so the very first count (a fresh process's first insert) and a
`flush(settle=True)` (before reading the counts back) wait for what was sent.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any, Callable


class Coalescer:
    def __init__(self, send: Callable[..., Any], width: int, every: float = 0.05,
                 clock: Callable[[], float] = time.monotonic, wait: Callable[[Any], Any] | None = None) -> None:
        self.send, self.every, self.clock, self.wait = send, every, clock, wait
        # handles of the latest sends not waited for (older ones were sent seconds ago)
        self._unsettled: deque = deque(maxlen=64)
        self._zero = (0,) * width
        self._pending = self._zero  # summed counts not yet sent
        self._sent_at = -float("inf")
        self._lock = threading.Lock()  # callers on several threads (a prefetch thread) sum safely

    @property
    def pending(self) -> tuple[int, ...]:
        return self._pending

    def add(self, *counts: int) -> None:
        """Count; send the sum if the last send is `every` seconds old (the first add at once)."""
        with self._lock:
            self._pending = tuple(a + b for a, b in zip(self._pending, counts))
            first = self._sent_at == -float("inf")
            due = self.clock() - self._sent_at >= self.every
        if due:
            self.flush(settle=first)

    def flush(self, settle: bool = False) -> None:
        """Send what is pending now (nothing if nothing is); with `settle`, also wait until
        everything sent so far was applied. Sends and waits run outside the lock."""
        with self._lock:
            pending, self._pending = self._pending, self._zero
            if pending != self._zero:
                self._sent_at = self.clock()
        if pending != self._zero:
            handle = self.send(*pending)
            with self._lock:
                self._unsettled.append(handle)
        if settle and self.wait is not None:
            with self._lock:
                handles = list(self._unsettled)
                self._unsettled.clear()
            if handles:
                self.wait(handles)
