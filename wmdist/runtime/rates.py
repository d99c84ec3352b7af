"""Per-second rates of the run's counters over a trailing window of time.

Collectors report env steps in chunks (a segment of a few hundred steps every several
seconds), while the driver samples its counters every couple of seconds. A rate taken
between two neighbouring samples then reads 0 on most of them and a spike on the rest,
so the console and `wmdist_env_steps_per_second` average over a window instead.
"""
from __future__ import annotations

import collections
from typing import Mapping

RATE_WINDOW_SECONDS = 30.0  # spans several collector segments even when the learner rate-limits them


class WindowRates:
    """Rates of monotone counters over the last `window_s` seconds (or since the start, if shorter)."""

    def __init__(self, window_s: float, now: float, counts: Mapping[str, float]) -> None:
        if not window_s > 0:
            raise ValueError(f"window_s must be > 0, got {window_s}")
        self.window_s = float(window_s)
        # (time, counts) samples, oldest first; the first one is the window's base
        self._samples: collections.deque[tuple[float, dict[str, float]]] = collections.deque([(now, dict(counts))])

    def update(self, now: float, counts: Mapping[str, float]) -> dict[str, float]:
        """Record the counters at `now` and return each one's per-second rate over the window."""
        self._samples.append((now, dict(counts)))
        # Keep the newest sample that is at least a window old as the base: the span is
        # [window, window + one sampling interval), never shorter once the run is that old.
        while len(self._samples) > 2 and now - self._samples[1][0] >= self.window_s:
            self._samples.popleft()
        t0, base = self._samples[0]
        dt = now - t0
        if dt <= 0:
            return {k: 0.0 for k in counts}
        return {k: (float(v) - base.get(k, float(v))) / dt for k, v in counts.items()}
