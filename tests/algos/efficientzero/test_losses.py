"""The consistency loss's gradients (none into the target branch, some into the dynamics),
its mask, and the learner's switches."""
import numpy as np
import pytest
import torch

from tests.algos.efficientzero.common import small_algo
from tests.algos.muzero.helpers import random_batch
from wmdist.algos.efficientzero.losses import consistency_loss

torch.set_num_threads(1)


def _grads(module: torch.nn.Module) -> float:
    return sum(float(p.grad.abs().sum()) for p in module.parameters() if p.grad is not None)


def _unroll(net, b=6, k=3):
    obs0 = torch.randn(b, 3)
    s = net.represent(obs0).detach()  # the unroll starts at a fixed latent: only g and the heads train
    latents = []
    for _ in range(k):
        s, _ = net.transition(s, torch.randint(0, 3, (b,)))
        latents.append(s)
    return latents


def test_consistency_sends_gradient_into_the_dynamics_and_none_into_the_target_branch():
    torch.manual_seed(0)
    net = small_algo().make_learner().net
    latents = _unroll(net)
    next_obs = torch.randn(6, 3, 3, requires_grad=True)  # [B, K, obs]
    loss = consistency_loss(net, latents, next_obs, torch.ones(6, 3)).mean()
    loss.backward()
    assert next_obs.grad is None  # the target branch is computed under stop-gradient
    assert _grads(net.base.repr_net) == 0.0  # h is only on the target branch here
    assert _grads(net.base.dyn_net) > 0  # the predicted latents train the dynamics
    assert _grads(net.consistency.predictor) > 0 and _grads(net.consistency.projector) > 0


def test_consistency_is_a_negative_cosine_and_masked():
    torch.manual_seed(1)
    net = small_algo().make_learner().net
    net.eval()  # fixed BN statistics: both branches project alike
    obs = torch.randn(4, 2, 3)
    latents = [net.represent(obs[:, k]) for k in range(2)]
    with torch.no_grad():
        target = net.consistency.project(net.represent(obs.flatten(0, 1))).view(4, 2, -1)
        pred = net.consistency.predict(net.consistency.project(torch.stack(latents, 1).flatten(0, 1))).view(4, 2, -1)
        cos = torch.nn.functional.cosine_similarity(pred, target, dim=-1)
    mask = torch.tensor([[1.0, 1.0], [1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    got = consistency_loss(net, latents, obs, mask)
    assert torch.allclose(got, -(cos * mask).sum(1) / 2, atol=1e-6)
    assert got[2] == 0.0
    zero = consistency_loss(net, latents, obs, torch.zeros(4, 2)).sum()
    net.zero_grad()
    zero.backward()
    assert _grads(net) == 0.0  # masked steps train nothing


@pytest.mark.parametrize("kw,present,absent", [
    ({}, {"consistency_loss"}, set()),
    ({"consistency_weight": 0.0, "value_prefix": False}, set(), {"consistency_loss"}),
])
def test_learner_switches(kw, present, absent):
    algo = small_algo(off_policy_correction=False, **kw)
    learner = algo.make_learner()
    net = learner.net
    assert (net.prefix is not None) == algo.config.value_prefix
    assert (net.consistency is not None) == (algo.config.consistency_weight > 0)
    assert (net.base.reward_head is None) == algo.config.value_prefix  # the LSTM replaces the reward head
    batch = random_batch(np.random.default_rng(0), 16, 10, 3)
    first = learner.update(batch).metrics
    for _ in range(30):
        last = learner.update(batch).metrics
    assert present <= set(first) and not (absent & set(first))
    assert last["loss"] < first["loss"]  # it learns on a fixed batch


def test_learner_uses_reanalyzed_value_targets_where_set():
    algo = small_algo()
    learner = algo.make_learner()
    batch = random_batch(np.random.default_rng(2), 32, 10, 3)
    acting = batch["mask"] & ~batch["last"]
    batch["value_target"] = np.where(acting, 7.0, 0.0).astype(np.float32)
    batch["value_target_set"] = acting.copy()
    assert learner.update(batch).metrics["value_target"] == pytest.approx(7.0)  # z at k = 0 is the stored one
    batch["value_target_set"][:] = False
    assert learner.update(batch).metrics["value_target"] != pytest.approx(7.0)  # n-step targets otherwise


def test_training_unroll_resets_the_lstm_every_horizon_steps():
    """In the unroll the LSTM state is zero exactly before steps k with (k-1) % horizon == 0,
    as in the search (the parent s^{k-1} at a depth that is a multiple of the horizon)."""
    from wmdist.search.api import SearchConfig

    algo = small_algo(search=SearchConfig(num_simulations=2, lstm_horizon=2), unroll_steps=5)
    learner = algo.make_learner()
    net = learner.net
    zero_at, real = [], net.recurrent_inference_prefix

    def spy(s, a, state):
        zero_at.append(not state[0].any() and not state[1].any())
        return real(s, a, state)

    net.recurrent_inference_prefix = spy
    learner.update(random_batch(np.random.default_rng(4), 8, 12, 3))
    assert zero_at == [True, False, True, False, True]  # k = 1..5
