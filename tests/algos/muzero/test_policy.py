"""Acting: the temperature schedule by env steps, visit-count sampling, greedy evaluation."""
import numpy as np
import torch

from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.algos.muzero.policy import select_actions, temperature_at
from wmdist.envs.spec import EnvSpec
from wmdist.search.api import SearchConfig

torch.set_num_threads(1)


def test_temperature_schedule_by_env_steps():
    cfg = MuZeroConfig(visit_temperatures=[1.0, 0.5, 0.25], temperature_env_steps=[100, 200])
    assert [temperature_at(cfg, s) for s in (0, 99, 100, 199, 200, 10**6)] == [1.0, 1.0, 0.5, 0.5, 0.25, 0.25]


def test_select_actions_follows_counts_at_temperature():
    rng = np.random.default_rng(0)
    counts = np.tile(np.array([[30, 10, 0]]), (20000, 1))
    a1 = select_actions(counts, np.ones(20000), rng)
    a_half = select_actions(counts, np.full(20000, 0.5), rng)
    greedy = select_actions(counts, np.zeros(20000), rng)
    assert abs((a1 == 0).mean() - 0.75) < 0.02  # N^(1/1): 30/40
    assert abs((a_half == 0).mean() - 0.9) < 0.02  # N^2: 900/1000
    assert (a1 != 2).all() and (greedy == 0).all()  # never an unvisited action; T=0 is argmax


def test_greedy_policy_is_deterministic_and_explore_is_not():
    spec = EnvSpec(id="test:vec", obs_shape=(4,), obs_dtype="float32", obs_kind="vector", num_actions=3)
    cfg = MuZeroConfig(search=SearchConfig(num_simulations=10), latent_dim=8, hidden=[16], value_support=5,
                       reward_support=3)
    policy = MuZero(spec, cfg, seed=0).make_policy()
    obs = np.random.default_rng(0).normal(size=(16, 4)).astype(np.float32)
    first = np.ones(16, bool)
    g1, ex = policy.act(obs, first, None, None, explore=False)
    g2, _ = policy.act(obs, first, None, None, explore=False)
    assert (g1 == g2).all()
    assert ex["search_policy"].shape == (16, 3) and ex["search_value"].shape == (16,)
    np.testing.assert_allclose(ex["search_policy"].sum(-1), 1.0, atol=1e-6)
    explored = np.stack([policy.act(obs, first, None, None, explore=True)[0] for _ in range(5)])
    assert (explored != g1).any()  # root noise and sampling at temperature 1


def test_greedy_fraction_makes_the_last_envs_of_a_collector_act_on_the_argmax_of_their_visits():
    from wmdist.algos.greedy_share import greedy_envs

    assert [greedy_envs(0.25, e) for e in (8, 4, 1)] == [2, 1, 1]  # a positive share is never rounded to 0
    assert greedy_envs(0.0, 8) == 0 and greedy_envs(1.0, 8) == 8
    spec = EnvSpec(id="test:vec", obs_shape=(4,), obs_dtype="float32", obs_kind="vector", num_actions=3)
    cfg = MuZeroConfig(search=SearchConfig(num_simulations=12), latent_dim=8, hidden=[16], value_support=5,
                       reward_support=3, greedy_fraction=0.25)
    policy = MuZero(spec, cfg, seed=0).make_policy()
    seen = []  # (visit counts, actions) of each exploring call, read off the searcher's result
    run = policy.searcher.run

    def spy(*args, **kw):
        res = run(*args, **kw)
        seen.append(res.visit_counts.copy())
        return res

    policy.searcher.run = spy
    obs = np.random.default_rng(1).normal(size=(8, 4)).astype(np.float32)
    acted = [policy.act(obs, np.zeros(8, bool), None, None, explore=True)[0] for _ in range(40)]
    counts, actions = np.stack(seen), np.stack(acted)  # [40, 8, 3], [40, 8]
    on_argmax = actions == counts.argmax(-1)  # [40, 8]
    assert on_argmax[:, 6:].all()  # envs 6 and 7: always the most visited action
    assert not on_argmax[:, :6].all()  # the others still sample at temperature 1
