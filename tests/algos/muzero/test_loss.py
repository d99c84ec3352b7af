"""The unroll loss on tiny hand-computed batches, and the 1/2 gradient scale into the dynamics."""
import math

import pytest
import torch

from wmdist.algos.muzero.losses import LossTargets, LossWeights, unroll_loss
from wmdist.algos.muzero.networks import MLPNet
from wmdist.nets.support import h_inv

torch.set_num_threads(1)
LOG2, LOG3 = math.log(2), math.log(3)


def _targets(b, k, value, vw, rw, pw, a=2):
    return LossTargets(
        actions=torch.zeros(b, k, dtype=torch.int64),
        value=torch.full((b, k + 1), value), value_w=torch.tensor([vw] * b, dtype=torch.float32),
        reward=torch.zeros(b, k + 1), reward_w=torch.tensor([rw] * b, dtype=torch.float32),
        policy=torch.full((b, k + 1, a), 1.0 / a), policy_w=torch.tensor([pw] * b, dtype=torch.float32),
    )


def test_loss_uniform_heads_hand_computed():
    """Zero-initialised heads predict uniform distributions, so each cross-entropy is log(atoms):
    value/reward over 3 atoms (support 1) = log 3, policy over 2 actions = log 2."""
    torch.manual_seed(0)
    net = MLPNet(obs_dim=4, num_actions=2, latent_dim=8, hidden=[8], value_atoms=3, reward_atoms=3)
    tgt = _targets(3, 2, value=0.0, vw=[1, 1, 1], rw=[0, 1, 1], pw=[1, 1, 0])
    out = unroll_loss(net, torch.randn(3, 4), tgt, LossWeights(value=0.25, reward=1.0, policy=1.0), 1, 1)
    # value: 0.25 * (1 + 1/2 + 1/2) log3; reward: (1/2 + 1/2) log3; policy: (1 + 1/2) log2
    want = 0.25 * 2 * LOG3 + LOG3 + 1.5 * LOG2
    assert torch.allclose(out.per_sample, torch.full((3,), want), atol=1e-6)


def test_loss_two_hot_value_hand_computed():
    """Value head fixed at softmax [1/4, 1/2, 1/4]; target h(z) = 0.5 -> two-hot [0, 1/2, 1/2]:
    CE = -(1/2 log 1/2 + 1/2 log 1/4) = 1.5 log 2 at every step; K = 1 -> (1 + 1) * 1.5 log 2."""
    net = MLPNet(obs_dim=4, num_actions=2, latent_dim=8, hidden=[8], value_atoms=3, reward_atoms=3)
    with torch.no_grad():
        net.value_head[-1].bias.copy_(torch.tensor([0.0, LOG2, 0.0]))
    z = float(h_inv(torch.tensor(0.5, dtype=torch.float64)))
    tgt = _targets(2, 1, value=z, vw=[1, 1], rw=[0, 0], pw=[0, 0])
    out = unroll_loss(net, torch.randn(2, 4), tgt, LossWeights(), 1, 1)
    assert torch.allclose(out.per_sample, torch.full((2,), 2 * 1.5 * LOG2), atol=1e-5)
    assert out.value0.tolist() == pytest.approx([0.0, 0.0], abs=1e-6)  # symmetric prediction -> 0


def _random_net(seed):
    torch.manual_seed(seed)
    net = MLPNet(obs_dim=4, num_actions=2, latent_dim=8, hidden=[16], value_atoms=5, reward_atoms=5)
    for head in (net.value_head, net.reward_head, net.policy_head):
        torch.nn.init.normal_(head[-1].weight)
    return net


def _grads(scale, weights_per_step):
    """Gradients of a loss whose per-step weights are `weights_per_step` ([K+1], step 0 first)."""
    net = _random_net(1)
    torch.manual_seed(2)
    obs = torch.randn(4, 4)
    k = len(weights_per_step) - 1
    tgt = _targets(4, k, value=1.5, vw=weights_per_step, rw=weights_per_step, pw=weights_per_step)
    tgt.actions = torch.tensor([[0, 1, 1, 0][:k]] * 4) if k <= 4 else torch.zeros(4, k, dtype=torch.int64)
    out = unroll_loss(net, obs, tgt, LossWeights(dynamics_grad_scale=scale), 2, 2)
    out.per_sample.sum().backward()
    return {n: p.grad.clone() for n, p in net.named_parameters()}


def test_gradient_into_dynamics_is_halved():
    full, half = _grads(1.0, [0, 1]), _grads(0.5, [0, 1])
    repr_names = [n for n in full if n.startswith("repr_net")]
    assert repr_names
    for n in repr_names:  # everything reaching h passes the one scaled dynamics input
        assert torch.allclose(half[n], 0.5 * full[n], atol=1e-7), n
    for n in full:  # the dynamics' and heads' own gradients are untouched
        if not n.startswith("repr_net"):
            assert torch.allclose(half[n], full[n], atol=1e-7), n
    assert any(full[n].abs().sum() > 0 for n in repr_names)


def test_gradient_scale_compounds_over_the_unroll():
    """The representation sees 1/2 of step 1's gradient and 1/4 of step 2's; the loss of
    step 0 reaches it unscaled."""
    n = "repr_net.0.weight"
    for weights, factor in (([0, 0, 1], 0.25), ([0, 1, 0], 0.5), ([1, 0, 0], 1.0)):
        full, half = _grads(1.0, weights), _grads(0.5, weights)
        assert full[n].abs().sum() > 0
        assert torch.allclose(half[n], factor * full[n], atol=1e-7), weights
