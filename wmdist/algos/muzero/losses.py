"""The MuZero loss over a K-step unroll (paper Eq. 1, with the Appendix G scalings).

    l = sum_{k=0..K} c_k [ w_r l_r(u_{t+k}, r^k) + w_v l_v(z_{t+k}, v^k) + w_p l_p(pi_{t+k}, p^k) ]

Every l is a cross-entropy against a categorical target: value and reward as two-hot
targets of h(x) on their supports, policy against the search's visit distribution.
c_0 = 1 and c_k = 1/K for the recurrent steps (the paper scales those gradients by 1/K);
the hidden state entering each dynamics call has its gradient scaled by 1/2.
Weight decay (the c||theta||^2 term) lives in the optimiser.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import torch
from torch.nn import functional as F

from wmdist.algos.muzero.networks import MuZeroNet, scale_gradient
from wmdist.nets.support import scalar_to_support, support_to_scalar


@dataclass
class LossTargets:
    """Torch views of the unroll targets (see targets.UnrollTargets)."""

    actions: torch.Tensor  # [B, K] int64
    value: torch.Tensor  # [B, K+1] scalar value targets z
    value_w: torch.Tensor  # [B, K+1]
    reward: torch.Tensor  # [B, K+1] (column 0 unused)
    reward_w: torch.Tensor  # [B, K+1]
    policy: torch.Tensor  # [B, K+1, A]
    policy_w: torch.Tensor  # [B, K+1]


@dataclass
class LossWeights:
    value: float = 1.0
    reward: float = 1.0
    policy: float = 1.0
    dynamics_grad_scale: float = 0.5


@dataclass
class LossOut:
    per_sample: torch.Tensor  # [B] total loss of each sample (before importance weights)
    value_loss: torch.Tensor  # [] means over the batch, for metrics
    reward_loss: torch.Tensor
    policy_loss: torch.Tensor
    value0: torch.Tensor  # [B] predicted scalar value at k = 0 (detached; for priorities)
    latents: list[torch.Tensor] = field(default_factory=list)  # K x [B, *latent]: s^1..s^K (with gradient)


# (latent s^{k-1}, action a^k [B], k) -> (s^k, reward logits, policy logits, value logits)
StepFn = Callable[[torch.Tensor, torch.Tensor, int], tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]


def _ce(logits: torch.Tensor, target_probs: torch.Tensor) -> torch.Tensor:
    """[B, N] logits, [B, N] probabilities -> [B] cross-entropy (computed in fp32)."""
    return -(target_probs * F.log_softmax(logits.float(), dim=-1)).sum(-1)


def unroll_loss(
    net: MuZeroNet,
    obs: torch.Tensor,  # [B, *obs_shape] observations at t0
    tgt: LossTargets,
    weights: LossWeights,
    value_support: int,
    reward_support: int,
    step: StepFn | None = None,
) -> LossOut:
    """`step` replaces `net.recurrent_inference` in the unroll (EfficientZero: an LSTM
    value-prefix head carries its state along; its "reward" logits are the prefix's)."""
    if step is None:
        step = lambda s, a, k: net.recurrent_inference(s, a)  # noqa: E731
    k_steps = tgt.actions.shape[1]
    latent, policy_logits, value_logits = net.initial_inference(obs)
    value0 = support_to_scalar(value_logits.detach().float(), value_support)
    value_t = scalar_to_support(tgt.value, value_support)  # [B, K+1, 2Sv+1]
    reward_t = scalar_to_support(tgt.reward, reward_support)  # [B, K+1, 2Sr+1]
    lv = _ce(value_logits, value_t[:, 0]) * tgt.value_w[:, 0]
    lp = _ce(policy_logits, tgt.policy[:, 0]) * tgt.policy_w[:, 0]
    lr = torch.zeros_like(lv)
    latents = []
    for k in range(1, k_steps + 1):
        latent = scale_gradient(latent, weights.dynamics_grad_scale)
        latent, reward_logits, policy_logits, value_logits = step(latent, tgt.actions[:, k - 1], k)
        latents.append(latent)
        c = 1.0 / k_steps
        lv = lv + c * _ce(value_logits, value_t[:, k]) * tgt.value_w[:, k]
        lr = lr + c * _ce(reward_logits, reward_t[:, k]) * tgt.reward_w[:, k]
        lp = lp + c * _ce(policy_logits, tgt.policy[:, k]) * tgt.policy_w[:, k]
    per_sample = weights.value * lv + weights.reward * lr + weights.policy * lp
    return LossOut(per_sample, lv.mean().detach(), lr.mean().detach(), lp.mean().detach(), value0, latents)
