"""ReplayShard on both backends (memory and a real redis-server): sampling, weights, eviction,
masks, write-back, stale write-back, bad input."""
from __future__ import annotations

import numpy as np
import pytest
from replay_helpers import T, make_batch
from scipy.stats import chisquare


def _obs_ids(sample: dict) -> np.ndarray:
    return sample["data"]["obs"][:, 0, 0].astype(int)  # sequence id encoded in obs[.., 0, 0]


def test_uniform_frequencies_chi_square(make_shard):
    sh = make_shard(capacity=32, seed=1)
    sh.insert(make_batch(20))
    s = sh.sample(8000)
    counts = np.bincount(_obs_ids(s), minlength=20)
    assert counts.sum() == 8000 and chisquare(counts).pvalue > 1e-3
    assert np.all(s["is_weight"] == 1)


def test_prioritized_frequencies_and_is_weights(make_shard):
    alpha, beta = 0.7, 0.5
    sh = make_shard(capacity=16, sampler="prioritized", alpha=alpha, seed=2)
    sh.insert(make_batch(10))
    first = sh.sample(10)
    assert np.allclose(first["is_weight"], 1.0)  # new items all sit at the max priority
    # set priorities p_i = i + 1 through write-back by key and stamp
    slots = np.arange(10)
    assert sh.update_priorities(slots, sh.stamp[slots], np.arange(1, 11, dtype=float)) == 10
    s = sh.sample(20000, beta=beta)
    ids = _obs_ids(s)
    p_alpha = np.arange(1, 11, dtype=float) ** alpha
    P = p_alpha / p_alpha.sum()  # P(i) = p_i^alpha / sum_k p_k^alpha
    assert chisquare(np.bincount(ids, minlength=10), P * 20000).pvalue > 1e-3
    assert np.allclose(s["is_weight"], (10 * P[ids]) ** -beta, rtol=1e-5)  # w_i = (N P(i))^-beta


def test_fifo_eviction_counts_and_capacity(make_shard):
    sh = make_shard(capacity=8)
    for start in range(0, 20, 5):
        sh.insert(make_batch(5, start=start))
    st = sh.stats()
    assert st["size_sequences"] == 8 and st["inserts"] == 20 and st["drops_evicted"] == 12
    assert set(_obs_ids(sh.sample(400))) == set(range(12, 20))  # only the newest 8 remain


def test_masks_and_padding_survive_storage(make_shard):
    sh = make_shard(capacity=8)
    sh.insert(make_batch(3, steps=np.array([T, 3, 1])))
    assert sh.stats()["size_steps"] == T + 4
    s = sh.sample(200)
    for i in range(3):
        rows = _obs_ids(s) == i
        n = [T, 3, 1][i]
        assert rows.any()
        assert np.all(s["mask"][rows].sum(1) == n)
        assert np.all(s["data"]["last"][rows][:, n - 1]) and np.all(s["data"]["reward"][rows][:, n:] == 0)
        assert np.all(s["data"]["obs"][rows][:, :n, 1] == np.arange(n))


def test_write_back_and_stale_write_back(make_shard):
    sh = make_shard(capacity=4)
    sh.insert(make_batch(4))
    s = sh.sample(4)
    new = {"root_value": np.full((4, T), 7.0, np.float32)}
    assert sh.write_back(s["slots"], s["stamps"], new) == 4
    fresh = sh.sample(50)
    hit = np.isin(fresh["slots"], s["slots"])
    assert np.all(fresh["data"]["root_value"][hit] == 7.0)
    # overwrite two of the sampled slots with new sequences: their write-back is stale
    stale = sh.sample(4)
    sh.insert(make_batch(2, start=100))
    applied = sh.write_back(stale["slots"], stale["stamps"], {"root_value": np.full((4, T), -1.0, np.float32)})
    n_stale = int(np.isin(stale["slots"], [0, 1]).sum())
    assert applied == 4 - n_stale and sh.stats()["drops_stale_writeback"] == n_stale
    after = sh.sample(200)
    new_ids = _obs_ids(after) >= 100
    assert np.all(after["data"]["root_value"][new_ids] == 0)  # new sequences never got old targets
    assert sh.update_priorities(stale["slots"], stale["stamps"], np.ones(4)) == 4 - n_stale
    assert sh.stats()["drops_stale_priority"] == n_stale


@pytest.mark.parametrize("change, msg", [
    (lambda b: b.data.pop("reward"), "field 'reward' is missing"),
    (lambda b: b.data.update(obs=b.data["obs"].astype(np.float16)), "'obs': dtype float16"),
    (lambda b: b.data.update(action=b.data["action"][:, :-1]), r"'action': shape \(2, 7\)"),
    (lambda b: b.data.update(extra=b.data["reward"]), "unknown field 'extra'"),
    (lambda b: setattr(b, "mask", b.mask[:, :3]), "mask must be"),
    (lambda b: b.data.update(obs=np.zeros((2, T, 3), object)), "'obs': dtype object is not storable"),
])
def test_bad_input_rejected_at_insert(make_shard, change, msg):
    sh = make_shard(capacity=4)
    b = make_batch(2)
    change(b)
    with pytest.raises(ValueError, match=msg):
        sh.insert(b)
    assert sh.stats()["size_sequences"] == 0


def test_bad_write_back_and_priorities(make_shard):
    sh = make_shard(capacity=4)
    sh.insert(make_batch(2))
    s = sh.sample(2)
    with pytest.raises(ValueError, match="unknown field 'nope'"):
        sh.write_back(s["slots"], s["stamps"], {"nope": np.zeros((2, T), np.float32)})
    with pytest.raises(ValueError, match="'root_value': shape"):
        sh.write_back(s["slots"], s["stamps"], {"root_value": np.zeros((2, T + 1), np.float32)})
    with pytest.raises(ValueError, match="finite"):
        sh.update_priorities(s["slots"], s["stamps"], np.array([1.0, np.nan]))


def test_policy_lag_drops_are_counted(make_shard):
    sh = make_shard(capacity=8)
    b = make_batch(4)  # versions 0..3
    assert sh.insert(b, min_version=2) == 2 * T
    assert sh.stats()["drops_policy_lag"] == 2 and set(_obs_ids(sh.sample(100))) == {2, 3}
