"""Gumbel MuZero properties with a model whose root Q values are exact (BanditModel)."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.search.api import SearchConfig, search
from wmdist.search.testing import BanditModel


def _softmax(x: np.ndarray, mask: np.ndarray) -> np.ndarray:
    z = np.where(mask, x, -np.inf)
    e = np.exp(z - z.max(axis=-1, keepdims=True))
    return e / e.sum(axis=-1, keepdims=True)


def _sigma(q, logits, legal, visits, root_value, c_visit=50.0, c_scale=0.1):
    """sigma(completed q) straight from the paper: eq. 33 mixed value for unvisited actions,
    min-max rescaling over the legal actions, scale (c_visit + max N) * c_scale."""
    probs = _softmax(logits, legal)
    seen = visits > 0
    total = visits.sum(axis=-1)
    v_mix = (root_value + total / (probs * seen).sum(-1) * (probs * seen * q).sum(-1)) / (1 + total)
    completed = np.where(seen, q, v_mix[:, None])
    lo = np.where(legal, completed, np.inf).min(-1, keepdims=True)
    hi = np.where(legal, completed, -np.inf).max(-1, keepdims=True)
    rescaled = (completed - lo) / np.maximum(hi - lo, 1e-8)
    return (c_visit + visits.max(-1, keepdims=True)) * c_scale * rescaled


@pytest.mark.parametrize("num_actions,max_considered,sims", [(4, 16, 16), (8, 8, 16), (16, 4, 12), (16, 16, 2)])
def test_action_maximises_score_over_actions_left_by_halving(num_actions, max_considered, sims) -> None:
    batch = 64
    rng = np.random.default_rng(num_actions * 100 + sims)
    q = rng.normal(size=(batch, num_actions))
    logits = rng.normal(size=(batch, num_actions))
    legal = np.ones((batch, num_actions), dtype=bool)
    legal[::3, 0] = False
    config = SearchConfig(num_simulations=sims, gumbel=True, gumbel_max_considered=max_considered)
    seed = 7
    out = search(BanditModel(q).root_latent(), logits, np.zeros(batch), legal, None, BanditModel(q), config,
                 np.random.default_rng(seed))
    g = np.random.default_rng(seed).gumbel(size=(batch, num_actions))  # the search's draw (noise.py order)
    visits = out.visit_counts
    left = legal & (visits == visits.max(axis=1, keepdims=True))
    assert (left.sum(axis=1) >= 1).all()
    assert (left.sum(axis=1) <= 2).all() or sims < max_considered
    score = g + logits + _sigma(q, logits, legal, visits, np.zeros(batch))
    expected = np.where(left, score, -np.inf).argmax(axis=1)
    assert (out.action == expected).all()
    # Gumbel-top-k: the visited actions are the top-k of g + logits among the legal ones.
    k = min(max_considered, num_actions, sims)
    topk = np.argsort(-np.where(legal, g + logits, -np.inf), axis=1, kind="stable")[:, :k]
    for b in range(batch):
        considered = min(max_considered, legal[b].sum(), sims)
        assert set(np.flatnonzero(visits[b])) == set(topk[b, :considered].tolist())
    # Improved policy target = softmax(logits + sigma(completed q)) over legal actions.
    target = _softmax(logits + _sigma(q, logits, legal, visits, np.zeros(batch)), legal)
    np.testing.assert_allclose(out.policy, target, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("sims", [2, 4, 16])
def test_gumbel_policy_improvement(sims: int) -> None:
    """E[q(chosen)] over Gumbel draws >= E_{a ~ prior}[q(a)] (Danihelka et al. 2022, sec. 3)."""
    batch, num_actions = 4000, 16
    rng = np.random.default_rng(sims)
    q_row = rng.normal(size=num_actions)
    logits_row = -1.5 * q_row + rng.normal(size=num_actions)  # a prior that prefers bad actions
    q = np.tile(q_row, (batch, 1))
    logits = np.tile(logits_row, (batch, 1))
    legal = np.ones((batch, num_actions), dtype=bool)
    config = SearchConfig(num_simulations=sims, gumbel=True)
    model = BanditModel(q)
    out = search(model.root_latent(), logits, np.zeros(batch), legal, None, model, config, rng)
    prior = _softmax(logits_row, np.ones(num_actions, bool))
    prior_value = float(prior @ q_row)
    chosen_value = float(q_row[out.action].mean())
    stderr = float(q_row[out.action].std()) / np.sqrt(batch)
    assert chosen_value > prior_value + 3 * stderr, (chosen_value, prior_value)
    # More simulations do not hurt: the greedy limit is max q.
    assert chosen_value <= q_row.max() + 1e-9


def test_without_noise_gumbel_is_deterministic_and_greedy_on_exact_q() -> None:
    q = np.array([[0.1, 0.9, 0.5, -0.3]])
    model = BanditModel(q)
    config = SearchConfig(num_simulations=16, gumbel=True)
    out = search(model.root_latent(), np.zeros((1, 4)), np.zeros(1), np.ones((1, 4), bool), None, model, config,
                 np.random.default_rng(0), add_noise=False)
    assert out.action[0] == 1
    assert out.visit_counts[0].sum() == 16
    np.testing.assert_allclose(out.q_values[0], q[0], rtol=1e-6)
