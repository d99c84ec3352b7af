"""Short in-process runs: the world-model loss falls; checkpoints round-trip exactly."""
import copy

import numpy as np
import pytest
import torch

from dreamer_loop import run_loop, tiny_config
from wmdist.algos.base import NonFiniteLoss
from wmdist.algos.dreamer import Dreamer
from wmdist.bench.dreamer import bench_spec, random_batch


@pytest.mark.parametrize("version,env_id", [(3, "gym:CartPole-v1"), (2, "gym:CartPole-v1"), (1, "gym:Pendulum-v1")])
def test_world_model_loss_falls(version, env_id):
    torch.set_num_threads(1)
    _, metrics, _ = run_loop(env_id, tiny_config(version, model_lr=1e-3), env_steps=1600, updates_every=16)
    losses = np.array([m["recon_loss"] + m["reward_loss"] for m in metrics])
    assert len(losses) >= 60
    first, last = losses[:10].mean(), losses[-10:].mean()
    assert last < 0.6 * first, (first, last)
    assert all(np.isfinite(m["actor_loss"]) and np.isfinite(m["critic_loss"]) for m in metrics)


@pytest.mark.parametrize("discrete", [True, False])
def test_state_dict_round_trip_is_exact(discrete):
    spec = bench_spec(discrete)
    learner = Dreamer(spec, tiny_config(3)).make_learner()
    batch = random_batch(spec, 4, 12, seed=1)
    learner.update(batch)
    saved = copy.deepcopy(learner.state_dict())
    a = learner.update(batch).metrics
    fresh = Dreamer(spec, tiny_config(3), seed=7).make_learner()
    fresh.load_state_dict(saved)
    b = fresh.update(batch).metrics
    assert a == b
    for (k, x), (_, y) in zip(learner.state_dict()["wm"].items(), fresh.state_dict()["wm"].items()):
        assert torch.equal(x, y), k


def test_non_finite_batch_raises_before_any_change():
    spec = bench_spec(True)
    learner = Dreamer(spec, tiny_config(3)).make_learner()
    batch = random_batch(spec, 2, 8)
    batch["obs"][0, 3, 0] = np.nan
    before = copy.deepcopy(learner.state_dict()["wm"])
    with pytest.raises(NonFiniteLoss):
        learner.update(batch)
    for k, v in learner.state_dict()["wm"].items():
        assert torch.equal(v, before[k]), k


def test_bad_batch_is_one_clear_error():
    learner = Dreamer(bench_spec(True), tiny_config(3)).make_learner()
    batch = random_batch(bench_spec(True), 2, 8)
    del batch["terminal"]
    with pytest.raises(ValueError, match="terminal"):
        learner.update(batch)
