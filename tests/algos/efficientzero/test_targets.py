"""EfficientZero's targets against plain loops: value prefixes with resets, the corrected
horizon's golden values, the consistency mask."""
import numpy as np
import pytest

from tests.algos.muzero.helpers import random_batch
from wmdist.algos.efficientzero.targets import consistency_mask, corrected_horizon, value_prefix_targets
from wmdist.algos.muzero.targets import make_targets, sample_starts


@pytest.mark.parametrize("horizon", [1, 2, 3, 5, 8])
def test_value_prefix_targets_equal_a_plain_loop(horizon):
    rng = np.random.default_rng(horizon)
    reward = rng.normal(size=(6, 9)).astype(np.float32)  # K = 8
    got = value_prefix_targets(reward, horizon)
    for b in range(6):
        acc = 0.0
        assert got[b, 0] == 0.0
        for k in range(1, 9):
            if (k - 1) % horizon == 0:  # the LSTM restarts from zeros before this step
                acc = 0.0
            acc += float(reward[b, k])
            assert got[b, k] == pytest.approx(acc, abs=1e-5)


def test_value_prefix_resets_every_horizon_steps_on_unit_rewards():
    got = value_prefix_targets(np.ones((1, 12), np.float32), 5)
    assert got[0].tolist() == [0, 1, 2, 3, 4, 5, 1, 2, 3, 4, 5, 1]


def test_value_prefix_stays_flat_past_a_terminal():
    # the unroll targets' rewards are 0 beyond a terminal, so the prefix holds its last value
    batch = random_batch(np.random.default_rng(3), 32, 10, 3)
    t0, valid = sample_starts(batch["mask"], batch["last"], np.random.default_rng(1))
    tg = make_targets(batch, t0, valid, 5, 3, 0.99, 3, np.random.default_rng(2))
    prefix = value_prefix_targets(tg.reward, 5)
    absorbing = (tg.reward_w > 0) & (tg.policy_w == 0)
    for b, k in zip(*np.nonzero(absorbing)):
        if k > 1:
            assert prefix[b, k] == pytest.approx(prefix[b, k - 1] + tg.reward[b, k], abs=1e-6)


def test_corrected_horizon_golden_values():
    n, tau = 5, 30_000.0  # the authors' Atari numbers: tau = 0.3 x 100k
    age = np.array([0, 29_999, 30_000, 59_999, 60_000, 90_000, 119_999, 120_000, 10**9, -5])
    assert corrected_horizon(age, n, tau).tolist() == [5, 5, 4, 4, 3, 2, 2, 1, 1, 5]
    assert corrected_horizon(np.zeros((2, 3)), n, tau).tolist() == [[5] * 3] * 2  # fresh data keeps n
    assert (corrected_horizon(np.full(4, 10**7), n, 1.0) == 1).all()  # old data: 1, never 0
    with pytest.raises(ValueError, match="tau"):
        corrected_horizon(age, n, 0.0)


def test_consistency_mask_stops_at_the_episode_end():
    batch = random_batch(np.random.default_rng(5), 40, 12, 2)
    t0, valid = sample_starts(batch["mask"], batch["last"], np.random.default_rng(0))
    m = consistency_mask(batch, t0, valid, 5)
    for b in range(40):
        for k in range(1, 6):
            p = t0[b] + k
            inside = valid[b] and p < 12 and batch["mask"][b, p] and not batch["first"][b, p] \
                and not batch["last"][b, t0[b]:p].any()
            assert m[b, k - 1] == float(inside), (b, k)
