"""Reanalyzer and learner contracts: fresh targets from the latest weights, exact
checkpoint round trip, importance weights, non-finite losses refused."""
import copy

import numpy as np
import pytest
import torch

from tests.algos.muzero.helpers import random_batch
from tests.algos.muzero.loop import InProcessLoop
from wmdist.algos.base import NonFiniteLoss
from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.algos.muzero.reanalyzer import ROOT_BUCKET
from wmdist.envs.config import EnvConfig
from wmdist.envs.spec import EnvSpec
from wmdist.envs.factory import env_spec
from wmdist.nets.optim import OptimConfig
from wmdist.search.api import SearchConfig

torch.set_num_threads(1)
SPEC = EnvSpec(id="test:vec", obs_shape=(3,), obs_dtype="float32", obs_kind="vector", num_actions=3)


def _algo(spec=SPEC, **kw):
    cfg = MuZeroConfig(search=SearchConfig(num_simulations=6), optim=OptimConfig(kind="adam", lr=1e-2),
                       latent_dim=8, hidden=[16], value_support=5, reward_support=3, td_steps=3, **kw)
    return MuZero(spec, cfg, seed=0)


def test_reanalyze_with_the_same_weights_reproduces_greedy_search():
    env = EnvConfig(id="gym:CartPole-v1")
    algo = _algo(env_spec(env), reanalyze_noise=False)
    loop = InProcessLoop(algo, env, num_envs=4, seq_len=12, overlap=2)
    loop.learner.update(random_batch(np.random.default_rng(0), 8, 12, 2, obs_dim=4))  # non-trivial weights
    loop.policy.set_weights(loop.learner.get_weights(), 1)
    loop.collect(15, explore=False)  # no root noise: the search is deterministic
    batch = loop.sample(6)
    re = algo.make_reanalyzer()
    re.set_weights(loop.learner.get_weights(), 1)
    fresh = re.reanalyze(batch)
    acting = batch["mask"].astype(bool) & ~batch["last"]  # replay hands the learner a float mask
    assert fresh["search_policy"].shape == batch["search_policy"].shape
    np.testing.assert_allclose(fresh["search_policy"][acting], batch["search_policy"][acting], atol=1e-6)
    np.testing.assert_allclose(fresh["search_value"][acting], batch["search_value"][acting], atol=1e-5)
    assert (fresh["search_policy"][~acting] == 0).all() and (fresh["search_value"][~acting] == 0).all()
    # newer weights give different targets
    loop.learner.update(random_batch(np.random.default_rng(1), 8, 12, 2, obs_dim=4))
    re.set_weights(loop.learner.get_weights(), 2)
    assert not np.allclose(re.reanalyze(batch)["search_value"][acting], batch["search_value"][acting])


def test_reanalyze_searches_padded_batches_and_chunking_leaves_the_targets_unchanged():
    """Every search call gets a multiple of ROOT_BUCKET roots (its cached workspace is reused
    instead of a fresh buffer per call), and the padding roots change no real root's target."""
    env = EnvConfig(id="gym:CartPole-v1")
    algo = _algo(env_spec(env), reanalyze_noise=False)
    loop = InProcessLoop(algo, env, num_envs=4, seq_len=12, overlap=2)
    loop.collect(30, explore=False)
    batch = loop.sample(12)
    re = algo.make_reanalyzer()
    re.set_weights(loop.learner.get_weights(), 1)
    sizes, run = [], re.searcher.run
    re.searcher.run = lambda obs, *a, **k: (sizes.append(len(obs)), run(obs, *a, **k))[1]
    whole = re.reanalyze(batch)
    acting = int((batch["mask"].astype(bool) & ~batch["last"]).sum())
    assert acting > ROOT_BUCKET and sizes == [-(-acting // ROOT_BUCKET) * ROOT_BUCKET]
    sizes.clear()
    re.max_roots = ROOT_BUCKET
    chunked = re.reanalyze(batch)
    assert len(sizes) == -(-acting // ROOT_BUCKET) and set(sizes) == {ROOT_BUCKET}
    for k in ("search_policy", "search_value"):
        np.testing.assert_allclose(chunked[k], whole[k], atol=1e-6)


def test_reanalyze_noise_keeps_every_legal_action_in_the_targets_of_a_peaked_prior():
    """A prior that puts ~all mass on one action: without noise the search never tries the
    others, so the target is one-hot; with self-play's root noise the others get visits."""
    env = EnvConfig(id="gym:CartPole-v1")
    targets = {}
    for noise in (False, True):
        algo = _algo(env_spec(env), reanalyze_noise=noise)
        loop = InProcessLoop(algo, env, num_envs=4, seq_len=12, overlap=2)
        loop.collect(15, explore=False)
        batch = loop.sample(6)
        re = algo.make_reanalyzer()
        weights = loop.learner.get_weights()
        weights["policy_head.2.bias"] = weights["policy_head.2.bias"] + np.array([30.0, 0.0], np.float32)  # prior ~ [1, 0]
        re.set_weights(weights, 1)
        acting = batch["mask"].astype(bool) & ~batch["last"]  # replay hands the learner a float mask
        targets[noise] = re.reanalyze(batch)["search_policy"][acting]  # [N, A]
    assert (targets[False][:, 1] == 0).all()  # collapsed: action 1 never searched
    assert (targets[True][:, 1] > 0).mean() > 0.2


def test_learner_checkpoint_round_trip_is_exact():
    algo = _algo(bootstrap="target", target_update_every=2)
    learner = algo.make_learner()
    rng = np.random.default_rng(0)
    batches = [random_batch(rng, 8, 10, 3) for _ in range(3)]
    learner.update(batches[0])
    saved = copy.deepcopy(learner.state_dict())
    a = [learner.update(b).metrics["loss"] for b in batches[1:]]
    w_a = learner.get_weights()
    other = algo.make_learner()
    other.load_state_dict(saved)
    b = [other.update(b).metrics["loss"] for b in batches[1:]]
    assert a == b
    for k in w_a:
        np.testing.assert_array_equal(w_a[k], other.get_weights()[k])


def test_importance_weights_and_priorities():
    learner = _algo().make_learner()
    batch = random_batch(np.random.default_rng(0), 8, 10, 3)
    batch["is_weight"] = np.zeros(8, np.float32)
    before = learner.get_weights()
    res = learner.update(batch)
    assert res.metrics["loss"] == 0.0  # every sample weighted 0
    assert res.priorities.shape == (8,) and (res.priorities > 0).all()
    # Adam with zero gradients and no weight decay leaves the weights in place
    for k, v in learner.get_weights().items():
        np.testing.assert_allclose(v, before[k], atol=1e-7)


def test_non_finite_loss_is_refused_before_any_change():
    learner = _algo().make_learner()
    batch = random_batch(np.random.default_rng(0), 8, 10, 3)
    batch["reward"][:] = np.nan
    batch["search_value"][:] = np.nan
    before = learner.get_weights()
    with pytest.raises(NonFiniteLoss):
        learner.update(batch)
    for k, v in learner.get_weights().items():
        np.testing.assert_array_equal(v, before[k])


def test_bad_inputs_are_clear_errors():
    learner = _algo().make_learner()
    batch = random_batch(np.random.default_rng(0), 4, 6, 3)
    del batch["search_policy"]
    with pytest.raises(ValueError, match="search_policy"):
        learner.update(batch)
    cont = EnvSpec(id="test:cont", obs_shape=(3,), obs_dtype="float32", obs_kind="vector", action_shape=(2,),
                   action_low=(-1.0, -1.0), action_high=(1.0, 1.0))
    with pytest.raises(ValueError, match="discrete"):
        _algo(cont).validate()
    with pytest.raises(ValueError, match="visit_temperatures"):
        MuZeroConfig(visit_temperatures=[1.0], temperature_env_steps=[10]).validate()


def test_bf16_autocast_update_is_finite_and_moves_weights():
    learner = _algo(bf16=True).make_learner()
    before = learner.get_weights()
    res = learner.update(random_batch(np.random.default_rng(0), 8, 10, 3))
    assert np.isfinite(res.metrics["loss"]) and res.metrics["loss"] > 0
    assert any(not np.allclose(v, before[k]) for k, v in learner.get_weights().items())
