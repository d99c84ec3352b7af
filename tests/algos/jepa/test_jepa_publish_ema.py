"""JEPA's `publish_ema`: the evaluator plans with, and checkpoints keep, a Polyak average of the
learner's weights, with BatchNorm statistics re-estimated for the average itself."""
from __future__ import annotations

import numpy as np
import torch

from tests.algos.jepa.test_jepa_batchnorm import _batch
from tests.algos.jepa.test_jepa_learning import small_config
from wmdist.algos.jepa import Jepa
from wmdist.algos.jepa.model import JepaModel, load_model
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec

DECAY = 0.9


def _learner(decay: float):
    spec = env_spec(EnvConfig(id="nav:open"))
    return spec, Jepa(spec, small_config(lr=3e-3, publish_ema=decay), seed=0).make_learner()


def test_published_weights_are_the_plain_per_update_average_with_statistics_for_it():
    spec, learner = _learner(DECAY)
    names = [n for n, _ in learner.model.named_parameters()]
    avg = {n: p.detach().clone() for n, p in learner.model.named_parameters()}  # the average starts at the weights
    batches = [_batch(s) for s in range(5)]
    for b in batches:
        learner.update(b)
        for n, p in learner.model.named_parameters():  # the slow, obvious loop
            avg[n] = DECAY * avg[n] + (1.0 - DECAY) * p.detach()
    published = learner.get_weights()
    for n in names:
        np.testing.assert_allclose(published[n], avg[n].numpy(), rtol=1e-5, atol=1e-6)
    own = dict(learner.model.named_parameters())
    assert any(not torch.allclose(own[n], avg[n]) for n in names)  # it is not the learner's own weights

    # the BatchNorm statistics belong to the average: its eval-mode embeddings of the kept frames
    # equal the average's batch-statistics ones
    policy_model = JepaModel(small_config(), spec.action_dim).eval()
    load_model(policy_model, published)
    seen = torch.as_tensor(np.concatenate([b["obs"][..., :3].reshape(-1, 64, 64, 3) for b in batches]))
    with torch.no_grad():
        learner.ema_model.train()
        want = learner.ema_model.encode(seen)
        learner.ema_model.eval()
        got = policy_model.encode(seen)
    torch.testing.assert_close(got, want, rtol=0.02, atol=0.02)


def test_the_average_survives_a_checkpoint_and_decay_zero_publishes_the_own_weights():
    _, learner = _learner(DECAY)
    for s in range(3):
        learner.update(_batch(s))
    state = learner.state_dict()
    _, restored = _learner(DECAY)
    restored.load_state_dict(state)
    for (n, a), (_, b) in zip(learner.ema_model.named_parameters(), restored.ema_model.named_parameters()):
        assert torch.equal(a, b), n

    _, plain = _learner(0.0)
    assert plain.ema_model is None
    for s in range(3):
        plain.update(_batch(s))
    published = plain.get_weights()
    for n, p in plain.model.named_parameters():
        np.testing.assert_array_equal(published[n], p.detach().numpy())
