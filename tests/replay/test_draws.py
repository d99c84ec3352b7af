"""DrawPools (the client's stock of shard draws) against fake shards and a fake clock: shard
calls are sent ahead of need and rarely, the union is sampled in proportion to each shard's
mass, draws are never older than `max_age`, and an empty shard is asked again later."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.replay.draws import DrawPools


class FakeShards:
    """S shards of `sizes[s]` equally likely items; a request draws when it is sent (like a
    shard call that runs at once) and remembers when, in take counts and clock time."""

    def __init__(self, sizes: list[int], clock) -> None:
        self.sizes, self.clock, self.rng = list(sizes), clock, np.random.default_rng(1)
        self.takes = 0  # takes done so far (set by the test)
        self.sent: list[tuple[int, int, int]] = []  # (shard, k, take index)
        self.leads: list[int] = []  # takes between each fetched request's send and its fetch

    def send(self, s: int, k: int) -> tuple[int, dict]:
        n = self.sizes[s]
        slots = self.rng.integers(0, n, k if n else 0)
        self.sent.append((s, k, self.takes))
        draw = {"slots": slots, "stamps": slots, "keys": [f"{s}:{self.clock()}:{x}" for x in slots],
                "mass": np.ones(slots.size), "size": n, "total": float(n)}
        return self.takes, draw

    def fetch(self, handles: list) -> list[dict]:
        self.leads += [self.takes - sent for sent, _ in handles]
        return [d for _, d in handles]


def _pools(sizes, ahead=16, max_age=1.0):
    t = [0.0]
    shards = FakeShards(sizes, lambda: t[0])
    return DrawPools(len(sizes), shards.send, shards.fetch, ahead, max_age, clock=lambda: t[0]), shards, t


@pytest.mark.parametrize("sizes", [[500], [100, 300], [100, 100, 200]])
def test_shard_calls_are_rare_and_sent_ahead_of_need(sizes):
    pools, shards, _ = _pools(sizes)
    rng, B, N = np.random.default_rng(0), 32, 400
    shard_of = []
    for i in range(N):
        shards.takes = i
        got = pools.take(B, rng)
        assert len(got[0]) == len(got[1]) == len(got[4]) == B and got[5] == sum(sizes)
        shard_of.append(got[0])
    S = len(sizes)
    calls = N / 16 * 1.25 + 2 * S  # about one call per 16 takes for the union, however many shards
    assert len(shards.sent) <= calls and pools.fetches <= calls
    assert pools.fetches <= N / 16 * 1.25 + 2  # the shards' requests go together: one fetch reads them all
    assert min(shards.leads[2 * S:]) >= 8  # once warm, each request waited for was sent 8+ takes earlier
    freq = np.bincount(np.concatenate(shard_of), minlength=S) / (N * B)
    assert np.allclose(freq, np.array(sizes) / sum(sizes), atol=0.01)


def test_draws_are_never_older_than_max_age():
    pools, shards, t = _pools([50, 50], ahead=16, max_age=1.0)
    rng = np.random.default_rng(0)
    for i in range(300):
        t[0] = i * 0.13  # a slow reader: a pool's stock outlives max_age
        shards.takes = i
        keys = pools.take(8, rng)[4]
        born = np.array([float(k.split(":")[1]) for k in keys])
        assert np.all(t[0] - born < 1.0), i


def test_an_empty_shard_is_asked_again_and_all_empty_is_none():
    pools, shards, t = _pools([0, 40])
    rng = np.random.default_rng(0)
    assert set(pools.take(16, rng)[0]) == {1}
    shards.sizes[0] = 40  # another client filled shard 0
    seen = set()
    for i in range(1, 60):
        t[0] = i * 0.1
        seen |= set(pools.take(16, rng)[0].tolist())
    assert seen == {0, 1}
    empty, _, _ = _pools([0, 0])
    assert empty.take(4, rng) is None
    pools.clear()
    assert all(len(p) == 0 and not p.reported for p in pools.pools) and not pools.inflight
