"""EfficientZero's additions to MuZero's unroll loss (wmdist/algos/muzero/losses.py).

- Value prefix: the unroll's step carries the LSTM state, zeroed before step k where
  (k-1) % horizon == 0; the "reward" loss of MuZero's unroll then scores prefixes.
- Consistency: l_sim = -sum_k c_k m_k cos(pred(proj(s^k)), sg(proj(h(o_{t+k})))), with
  c_k = 1/K as MuZero's other recurrent-step losses and m_k the consistency mask (0 past the
  episode's end). sg: the target branch is computed without gradient.
"""
from __future__ import annotations

import torch
from torch.nn import functional as F

from wmdist.algos.efficientzero.networks import EfficientZeroNet
from wmdist.algos.muzero.losses import StepFn


def prefix_step(net: EfficientZeroNet, batch: int, horizon: int, device: torch.device) -> StepFn:
    """An unroll step for `unroll_loss` that threads the value-prefix LSTM state."""
    state = net.initial_state(batch, device)

    def step(latent: torch.Tensor, action: torch.Tensor, k: int):
        nonlocal state
        if (k - 1) % horizon == 0:  # the parent s^{k-1} starts a segment (as in the search)
            state = net.initial_state(batch, device)
        nxt, state, prefix_logits, logits, value = net.recurrent_inference_prefix(latent, action, state)
        return nxt, prefix_logits, logits, value

    return step


def consistency_loss(
    net: EfficientZeroNet,
    latents: list[torch.Tensor],  # K x [B, *latent]: the dynamics' s^1..s^K (with gradient)
    next_obs: torch.Tensor,  # [B, K, *obs_shape]: o_{t+1}..o_{t+K}
    mask: torch.Tensor,  # [B, K] float
) -> torch.Tensor:
    """[B] per-sample negative cosine similarity, summed over k with weight 1/K and mask."""
    b, k = mask.shape
    heads = net.consistency
    with torch.no_grad():  # stop-gradient: the target branch trains nothing
        target = heads.project(net.represent(next_obs.flatten(0, 1))).view(b, k, -1)  # [B, K, P]
    pred = heads.predict(heads.project(torch.stack(latents, 1).flatten(0, 1))).view(b, k, -1)  # [B, K, P]
    cos = F.cosine_similarity(pred.float(), target.float(), dim=-1)  # [B, K]
    return -(cos * mask).sum(1) / k
