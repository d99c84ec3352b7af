"""Rate limiter: min_size, ratio band under concurrency, timeouts, close, checkpoint."""
from __future__ import annotations

import threading
import time

import pytest

from wmdist.replay.limiter import RateLimiter


def test_min_size_holds_samples_back():
    lim = RateLimiter(samples_per_insert=0, min_size=100, error_buffer=0)
    assert not lim.acquire_sample(1, timeout=0.05)
    assert lim.acquire_insert(1, timeout=0)
    lim.commit_insert(99)
    assert not lim.acquire_sample(1, timeout=0.01)
    lim.commit_insert(1)
    assert lim.acquire_sample(1, timeout=0)


def test_ratio_band_holds_under_concurrent_threads():
    spi, err, B, n = 4.0, 16.0, 8, 2
    lim = RateLimiter(spi, min_size=0, error_buffer=err)
    lo, hi = -err - n * spi, err + B  # a granted call overshoots by at most its own size
    seen = []
    stop = time.monotonic() + 1.0

    def inserter():
        while time.monotonic() < stop:
            if lim.acquire_insert(n, timeout=0.05):
                lim.commit_insert(n)
                seen.append(lim._error())

    def sampler():
        while time.monotonic() < stop:
            if lim.acquire_sample(B, timeout=0.05):
                seen.append(lim._error())

    threads = [threading.Thread(target=f) for f in (inserter, inserter, sampler)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    assert lim.total_sampled > 100 and lim.total_inserted > 25  # both sides made progress
    assert lo <= min(seen) and max(seen) <= hi
    assert abs(lim.total_sampled - spi * lim.total_inserted) <= hi + n * spi


def test_blocking_times_out_and_close_wakes_waiters():
    lim = RateLimiter(samples_per_insert=1, min_size=0, error_buffer=1)
    assert lim.acquire_insert(1) and lim.acquire_sample(1) and lim.acquire_sample(2)  # error -1 -> 0 -> 2
    t0 = time.monotonic()
    assert not lim.acquire_sample(1, timeout=0.2)  # learner is ahead: waits for inserts
    assert 0.18 <= time.monotonic() - t0 < 1.0
    assert lim.sample_wait_seconds >= 0.18
    result = []
    th = threading.Thread(target=lambda: result.append(lim.acquire_sample(1, timeout=None)))
    th.start()
    time.sleep(0.1)
    assert th.is_alive()  # blocked with no timeout...
    lim.close()
    th.join(2)
    assert not th.is_alive() and result == [False]  # ...and woken by close
    assert not lim.acquire_insert(1, timeout=None)


def test_insert_unblocks_sampler():
    lim = RateLimiter(samples_per_insert=1, min_size=0, error_buffer=0)
    assert lim.acquire_insert(1) and lim.acquire_sample(1) and lim.acquire_sample(1)  # error -1 -> 0 -> 1
    got = []
    th = threading.Thread(target=lambda: got.append(lim.acquire_sample(1, timeout=5)))
    th.start()
    time.sleep(0.05)
    assert not got
    lim.acquire_insert(1)
    th.join(5)
    assert got == [True]


def test_state_round_trip():
    a = RateLimiter(2, 10, 5)
    a.acquire_insert(3)
    a.commit_insert(30)
    a.acquire_sample(4)
    b = RateLimiter(2, 10, 5)
    b.load_state_dict(a.state_dict())
    assert b.state_dict() == a.state_dict() and b._error() == a._error()
    with pytest.raises(ValueError, match="missing"):
        b.load_state_dict({})
