"""The soak benchmark's train ratio when the rate limiter restarts mid-run: its counts start
from zero again, so the ratio is summed over the stretches between restarts and no window
spans one (a plain difference across the restart would be negative or meaningless)."""
from __future__ import annotations

import pytest

from wmdist.bench.soak import _ratios


def test_the_ratio_is_summed_over_the_stretches_between_limiter_restarts():
    # (elapsed s, sampled, inserted): ratio 3 before the restart at t = 40, 5 after it
    counts = [(0, 0, 0), (10, 30, 10), (20, 60, 20), (30, 90, 30),
              (40, 5, 1), (50, 55, 11), (60, 105, 21)]
    ratio, windows = _ratios(counts, start=0, window=10)
    assert ratio == pytest.approx((90 + 100) / (30 + 20))
    assert windows == pytest.approx([3, 3, 3, 5, 5])


def test_without_a_restart_it_is_the_plain_ratio_after_the_warm_up():
    counts = [(t, 4.0 * t, float(t)) for t in range(0, 100, 5)]
    ratio, windows = _ratios(counts, start=20, window=30)
    assert ratio == pytest.approx(4.0) and windows and all(w == pytest.approx(4.0) for w in windows)
    assert _ratios([(0, 0, 0)], start=0, window=10) == (None, [])
