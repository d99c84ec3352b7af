"""Search API contract: validation, policies at a temperature, latents, value-prefix resets."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from wmdist.search.api import SearchConfig, search
from wmdist.search.engine import sample_actions, visit_policy
from wmdist.search.noise import considered_visit_sequence, considered_visit_table
from wmdist.search.testing import HashModel

torch.set_num_threads(1)


def _run(model, batch=2, num_actions=3, **kw):
    latent, logits, value = model.root(batch, seed=1)
    legal = kw.pop("legal", np.ones((batch, num_actions), dtype=bool))
    config = kw.pop("config", SearchConfig(num_simulations=8))
    return search(latent, logits, value, legal, None, model, config, np.random.default_rng(0), **kw)


def test_sequential_halving_schedule() -> None:
    # m = 4, n = 16: two phases; 2 visits each to 4 actions, then 4 more each to 2.
    assert considered_visit_sequence(4, 16) == [0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5]
    assert considered_visit_sequence(1, 3) == [0, 1, 2]
    assert considered_visit_sequence(16, 2) == [0, 0]
    assert considered_visit_table(16, 50).shape == (17, 50)


def test_visit_policy_temperatures_and_sampling() -> None:
    counts = np.array([[1, 3, 0, 4], [2, 2, 2, 0]])
    legal = np.array([[True, True, True, True], [True, True, True, False]])
    np.testing.assert_allclose(visit_policy(counts, legal, 1.0)[0], [1 / 8, 3 / 8, 0, 4 / 8])
    np.testing.assert_allclose(visit_policy(counts, legal, 0.5)[0], np.array([1, 9, 0, 16]) / 26)
    greedy = visit_policy(counts, legal, 0.0)
    assert greedy[0].tolist() == [0, 0, 0, 1] and greedy[1].tolist() == [1, 0, 0, 0]  # ties -> lowest index
    tiny = visit_policy(counts, legal, 1e-4)  # no overflow at small temperatures
    assert np.isfinite(tiny).all() and tiny[0, 3] == 1.0
    draws = sample_actions(np.tile([[0.0, 0.25, 0.0, 0.75]], (20000, 1)), np.random.default_rng(0))
    assert set(draws.tolist()) == {1, 3}
    assert abs((draws == 3).mean() - 0.75) < 0.02


def test_greedy_action_and_outputs() -> None:
    out = _run(HashModel(3), temperature=0.0)
    assert out.action.tolist() == out.visit_counts.argmax(axis=1).tolist()
    assert out.visit_counts.sum(axis=1).tolist() == [8, 8]
    assert out.policy.dtype == np.float32 and out.q_values.shape == (2, 3) and out.root_value.shape == (2,)


def test_illegal_actions_are_never_visited_or_played() -> None:
    legal = np.array([[False, True, False], [True, False, False]])
    out = _run(HashModel(3), legal=legal, config=SearchConfig(num_simulations=20, dirichlet_alpha=1.0))
    assert not out.visit_counts[~legal].any() and out.policy[~legal].max() == 0
    assert out.action.tolist() == [1, 0]
    assert (out.q_values[~legal] == 0).all()


def test_torch_and_tuple_latents_reach_recurrent_fn_in_their_structure() -> None:
    seen = []

    def recurrent_fn(latents, actions):
        state, (hidden,) = latents
        seen.append((type(state), state.dtype, type(hidden), hidden.shape))
        nxt = (state + torch.from_numpy(actions)[:, None].float(), [hidden * 2])
        return np.zeros(2), np.zeros(2), np.zeros((2, 3)), nxt

    root = (torch.zeros(2, 4), [np.ones((2, 2, 2), np.float16)])
    out = search(root, np.zeros((2, 3)), np.zeros(2), np.ones((2, 3), bool), None, recurrent_fn,
                 SearchConfig(num_simulations=5), np.random.default_rng(0))
    assert len(seen) == 5 and out.visit_counts.sum() == 10
    assert all(s == (torch.Tensor, torch.float32, np.ndarray, (2, 2, 2)) for s in seen)


def test_value_prefix_reset_flags_follow_the_horizon() -> None:
    """reset[b] is true exactly where the parent's depth is a multiple of lstm_horizon."""
    horizon = 2

    def recurrent_fn(latents, actions, reset):
        depth = latents[:, 0]
        assert (reset == (depth % horizon == 0)).all()
        return np.ones(len(actions)), np.zeros(len(actions)), np.zeros((len(actions), 2)), latents + 1

    config = SearchConfig(num_simulations=30, value_prefix=True, lstm_horizon=horizon, discount=1.0)
    out = search(np.zeros((3, 1)), np.zeros((3, 2)), np.zeros(3), np.ones((3, 2), bool), None, recurrent_fn,
                 config, np.random.default_rng(0), add_noise=False)
    # prefix 1 everywhere: the edge reward is 1 right after a reset (depths 1, 3, ...) and
    # 0 inside a segment, so Q >= 1, and > 1 once a depth-3 node is under the child.
    assert out.visit_counts.sum() == 90
    assert np.all(out.q_values >= 1.0) and out.q_values.max() > 1.0


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(legal=np.zeros((2, 3), bool)), "at least one legal"),
        (dict(legal=np.ones((2, 4), bool)), "legal must be"),
        (dict(temperature=-1.0), "temperature"),
    ],
)
def test_bad_input_is_one_clear_error(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        _run(HashModel(3), **kwargs)


def test_bad_model_output_and_config_are_clear_errors() -> None:
    def bad_shape(latents, actions):
        return np.zeros(2), np.zeros(2), np.zeros((2, 5)), latents

    def non_finite(latents, actions):
        return np.full(2, np.nan), np.zeros(2), np.zeros((2, 3)), latents

    for fn, match in ((bad_shape, "logits must have shape"), (non_finite, "non-finite")):
        with pytest.raises(ValueError, match=match):
            search(np.zeros((2, 1)), np.zeros((2, 3)), np.zeros(2), np.ones((2, 3), bool), None, fn,
                   SearchConfig(num_simulations=3), np.random.default_rng(0))
    with pytest.raises(ValueError, match="num_simulations"):
        SearchConfig(num_simulations=0)
    with pytest.raises(ValueError, match="unvisited_value"):
        SearchConfig(unvisited_value="mean")
