"""The reanalyzer's off-policy-corrected value targets against a plain loop (fake values),
the policy-refresh fraction, and stale write-backs dropped by replay's stamps."""
import numpy as np
import pytest

from tests.algos.efficientzero.common import SPEC, small_algo
from tests.algos.muzero.helpers import random_batch
from wmdist.algos.efficientzero.reanalyzer import EfficientZeroReanalyzer
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.shard import ReplayShard


class FakeValues(EfficientZeroReanalyzer):
    """The model's value of a stored observation is 3 x its first feature (isolates the targets)."""

    def values_at(self, batch, r, c):
        return 3.0 * batch["obs"][r, c, 0]


def _plain_targets(batch, n, tau, gamma):
    """One loop per step: l = clip(n - age // tau, 1, n); MuZero's n-step return with l."""
    b, t = batch["mask"].shape
    out = np.zeros((b, t))
    for i in range(b):
        real = np.flatnonzero(batch["mask"][i])
        end = real[-1]  # last real step of the window (its episode's last step if it has one)
        for s in range(t):
            if not batch["mask"][i, s] or batch["last"][i, s]:
                continue
            horizon = int(min(max(n - batch["age"][i, s] // tau, 1), n))
            m = min(horizon, end - s)
            z = sum(gamma ** (j - 1) * batch["reward"][i, s + j] for j in range(1, m + 1))
            if not (batch["terminal"][i, s + m] and batch["last"][i, s + m]):
                z += gamma ** m * 3.0 * batch["obs"][i, s + m, 0]
            out[i, s] = z
    return out


@pytest.mark.parametrize("seed", range(4))
def test_corrected_value_targets_equal_a_plain_loop(seed):
    rng = np.random.default_rng(seed)
    cfg = small_algo(td_steps=5, off_policy_tau_ratio=0.5, off_policy_training_steps=20).config  # tau = 10
    batch = random_batch(rng, 12, 14, 3)
    batch["age"] = rng.integers(0, 60, size=(12, 14))
    re = FakeValues(small_algo().make_reanalyzer().net, cfg, SPEC, seed)
    out = re.corrected_value_targets(batch)
    want = _plain_targets(batch, 5, 10, cfg.search.discount)
    acting = batch["mask"] & ~batch["last"]
    assert (out["value_target_set"] == acting).all()
    np.testing.assert_allclose(out["value_target"], want, rtol=1e-5, atol=1e-5)


def test_fresh_data_keeps_n_steps_and_old_data_one():
    rng = np.random.default_rng(9)
    cfg = small_algo(td_steps=4, off_policy_tau_ratio=1.0, off_policy_training_steps=100).config
    batch = random_batch(rng, 6, 12, 3)
    batch["mask"][:] = True
    batch["last"][:] = False
    batch["terminal"][:] = False
    batch["first"][:] = False
    re = FakeValues(small_algo().make_reanalyzer().net, cfg, SPEC, 0)
    g = cfg.search.discount
    for age, l in ((0, 4), (10**6, 1)):
        batch["age"] = np.full((6, 12), age)
        z = re.corrected_value_targets(batch)["value_target"]
        s = 2
        want = sum(g ** (j - 1) * batch["reward"][:, s + j] for j in range(1, l + 1)) + g ** l * 3 * batch["obs"][:, s + l, 0]
        np.testing.assert_allclose(z[:, s], want, rtol=1e-5)


def test_policy_refresh_fraction():
    rng = np.random.default_rng(1)
    batch = random_batch(rng, 8, 10, 3)
    batch["age"] = np.zeros((8, 10), np.int64)
    for frac, changed in ((0.0, False), (1.0, True)):
        re = small_algo(reanalyze_policy_fraction=frac).make_reanalyzer()
        out = re.reanalyze(batch)
        acting = batch["mask"] & ~batch["last"]
        differs = np.abs(out["search_policy"] - batch["search_policy"]).sum(-1) > 1e-6
        assert differs[acting].all() == changed and differs[acting].any() == changed
        assert set(out) == {"search_policy", "search_value", "value_target", "value_target_set"}


def test_reanalyzer_needs_ages_for_the_correction():
    batch = random_batch(np.random.default_rng(0), 2, 6, 3)
    with pytest.raises(ValueError, match="age"):
        small_algo().make_reanalyzer().reanalyze(batch)


def test_stale_corrected_write_back_is_dropped_and_counted():
    algo = small_algo()
    fields = algo.step_fields()
    t = 6
    rng = np.random.default_rng(0)

    def windows(n):
        data = random_batch(rng, n, t, 3)
        data = {k: data[k].astype(fields[k].dtype) for k in fields if k in data}
        data["value_target"] = np.zeros((n, t), np.float32)
        data["value_target_set"] = np.zeros((n, t), bool)
        mask = np.ones((n, t), bool)
        return SequenceBatch(data, mask, np.zeros(n, np.int64), np.arange(n, dtype=np.int64))

    shard = ReplayShard(fields, t, capacity=2)
    shard.insert(windows(2))
    s = shard.sample(2)
    batch = dict(s["data"], mask=s["mask"], age=np.zeros((2, t), np.int64))
    fresh = algo.make_reanalyzer().reanalyze(batch)
    shard.insert(windows(1))  # overwrites the oldest slot: its sampled stamp is stale now
    applied = shard.write_back(s["slots"], s["stamps"], fresh)
    stale = int((shard.stamp[s["slots"]] != s["stamps"]).sum())
    assert stale >= 1 and applied == 2 - stale
    assert shard.stats()["drops_stale_writeback"] == stale
