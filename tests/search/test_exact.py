"""The fast batched search equals the slow reference search bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.search.api import SearchConfig, search
from wmdist.search.noise import sample_root_noise
from wmdist.search.reference import reference_search
from wmdist.search.testing import HashModel


def _random_case(seed: int):
    r = np.random.default_rng(1000 + seed)
    batch = int(r.choice([1, 3, 8]))
    num_actions = int(r.choice([2, 5, 9]))
    legal = r.random((batch, num_actions)) < 0.7
    legal[np.arange(batch), r.integers(0, num_actions, batch)] = True  # at least one legal per row
    config = SearchConfig(
        num_simulations=int(r.integers(1, 41)),
        discount=float(r.choice([1.0, 0.997, 0.9])),
        gumbel=bool(r.random() < 0.5),
        gumbel_max_considered=int(r.choice([1, 2, 4, 16])),
        value_prefix=bool(r.random() < 0.3),
        lstm_horizon=int(r.choice([1, 2, 5])),
        unvisited_value=str(r.choice(["parent", "zero"])),
        dirichlet_alpha=float(r.choice([0.03, 0.25, 1.0])),
    )
    model = HashModel(num_actions, reward_scale=float(r.choice([0.0, 1.0, 5.0])),
                      value_prefix=config.value_prefix, torch_latents=bool(r.random() < 0.3))
    return dict(
        batch=batch, legal=legal, config=config, model=model,
        two_player=bool(r.random() < 0.5), add_noise=bool(r.random() < 0.7),
        to_play=r.integers(0, 2, batch), temperature=float(r.choice([0.0, 0.5, 1.0])),
    )


def _row(latent, b):
    if isinstance(latent, tuple):
        return tuple(np.asarray(x)[b] for x in latent)
    return np.asarray(latent)[b]


@pytest.mark.parametrize("seed", range(80))
def test_fast_search_equals_reference(seed: int) -> None:
    case = _random_case(seed)
    config, model, legal = case["config"], case["model"], case["legal"]
    latent, logits, value = model.root(case["batch"], seed)
    out = search(latent, logits, value, legal, case["to_play"], model, config, np.random.default_rng(seed),
                 temperature=case["temperature"], add_noise=case["add_noise"], two_player=case["two_player"])
    assert model.calls == config.num_simulations  # one batched model call per simulation
    dirichlet, gumbel = sample_root_noise(np.random.default_rng(seed), legal, config.dirichlet_alpha,
                                          config.gumbel, case["add_noise"])
    for b in range(case["batch"]):
        ref = reference_search(_row(latent, b), logits[b], value[b], legal[b], model.step, config,
                               dirichlet[b], gumbel[b], case["add_noise"], case["two_player"])
        assert out.visit_counts[b].tolist() == ref.visit_counts
        assert out.visit_counts[b].sum() == config.num_simulations
        assert not out.visit_counts[b][~legal[b]].any()
        assert out.root_value[b] == np.float32(ref.root_value)
        assert out.q_values[b].tolist() == np.asarray(ref.q_values, dtype=np.float32).tolist()
        if config.gumbel:
            assert out.action[b] == ref.gumbel_action
            assert out.policy[b].tolist() == np.asarray(ref.improved_policy, dtype=np.float32).tolist()
        assert legal[b, out.action[b]]


def test_rows_do_not_interact() -> None:
    """A row's result is the same alone and inside a batch of rows with other masks."""
    num_actions = 6
    model = HashModel(num_actions)
    latent, logits, value = model.root(5, seed=3)
    legal = np.ones((5, num_actions), dtype=bool)
    legal[1, :4] = False
    legal[3, 1::2] = False
    config = SearchConfig(num_simulations=30)
    kwargs = dict(temperature=0.0, add_noise=False, two_player=True)
    batched = search(latent, logits, value, legal, np.array([0, 1, 0, 1, 1]), model, config,
                     np.random.default_rng(0), **kwargs)
    for b in range(5):
        alone = search(latent[b:b + 1], logits[b:b + 1], value[b:b + 1], legal[b:b + 1], None, model, config,
                       np.random.default_rng(0), **kwargs)
        assert alone.visit_counts[0].tolist() == batched.visit_counts[b].tolist()
        assert alone.root_value[0] == batched.root_value[b]
