"""Sum tree: parent = sum of children after any updates; search matches a cumsum reference."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chisquare

from wmdist.replay.sumtree import SumTree


def _check_invariants(t: SumTree) -> None:
    internal = np.arange(1, t.leaves)
    assert np.allclose(t.tree[internal], t.tree[2 * internal] + t.tree[2 * internal + 1])
    assert np.isclose(t.total, t.values().sum())
    assert np.all(t.tree[t.leaves + t.capacity:] == 0)  # padding leaves never hold mass


@pytest.mark.parametrize("capacity", [1, 5, 64, 100])
def test_invariants_under_random_updates(capacity):
    rng = np.random.default_rng(capacity)
    t = SumTree(capacity)
    ref = np.zeros(capacity)
    for _ in range(50):
        slots = rng.integers(0, capacity, size=rng.integers(1, 8))
        vals = rng.random(slots.size) * (rng.random(slots.size) > 0.2)
        t.set(slots, vals)
        for s, v in zip(slots, vals):  # last write wins, as in a plain loop
            ref[s] = v
        _check_invariants(t)
        assert np.allclose(t.values(), ref)


def test_find_matches_cumsum_reference():
    rng = np.random.default_rng(0)
    t = SumTree(37)
    masses = rng.random(37) * (rng.random(37) > 0.3)
    t.set(np.arange(37), masses)
    u = rng.random(2000) * t.total
    expected = np.searchsorted(np.cumsum(masses), u, side="right")
    assert np.array_equal(t.find(u), expected)
    assert np.all(masses[t.find(u)] > 0)  # zero-mass leaves are never found


def test_sample_frequencies_chi_square():
    rng = np.random.default_rng(1)
    t = SumTree(10)
    masses = np.arange(1, 11, dtype=float)
    t.set(np.arange(10), masses)
    counts = np.bincount(t.sample(40_000, rng), minlength=10)
    assert chisquare(counts, masses / masses.sum() * counts.sum()).pvalue > 1e-3


def test_bad_input():
    t = SumTree(4)
    with pytest.raises(ValueError, match="out of range"):
        t.set(np.array([4]), np.array([1.0]))
    with pytest.raises(ValueError, match="finite"):
        t.set(np.array([0]), np.array([np.nan]))
    with pytest.raises(ValueError, match="empty"):
        t.sample(1, np.random.default_rng())
