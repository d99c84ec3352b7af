"""The world model's KL term with balancing and free nats/bits.

dyn = KL(sg(post) || prior) trains only the prior; rep = KL(post || sg(prior)) only the
posterior. Loss = kl_dyn * max(free, dyn) + kl_rep * max(free, rep).
- V1 (one KL, both sides trained, free nats 3): kl_dyn = kl_rep = 1.
- V2 (KL balancing alpha = 0.8, scale beta): kl_dyn = alpha beta, kl_rep = (1 - alpha) beta.
- V3 (free bits 1): kl_dyn = 0.5, kl_rep = 0.1, clipped per step (`free_avg = False`).
"""
from __future__ import annotations

from typing import Callable

import torch


def masked_mean(x: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """sum(x w) / max(sum(w), 1) over all elements (w broadcast to x)."""
    return (x * weight).sum() / weight.sum().clamp(min=1.0)


def kl_loss(
    kl: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],  # KL(p || q) per state -> [...]
    post: torch.Tensor,  # [B, T, stats]
    prior: torch.Tensor,  # [B, T, stats]
    weight: torch.Tensor,  # [B, T] mask (x importance weight)
    dyn_scale: float,
    rep_scale: float,
    free: float,
    free_avg: bool,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Returns (loss, mean dyn KL, mean rep KL); the two KL means are for logging."""
    dyn = kl(post.detach(), prior)  # [B, T]
    rep = kl(post, prior.detach())
    if free_avg:  # V1/V2: clip the batch mean (free nats)
        dyn_l = torch.clamp(masked_mean(dyn, weight), min=free)
        rep_l = torch.clamp(masked_mean(rep, weight), min=free)
    else:  # V3: clip every step (free bits)
        dyn_l = masked_mean(torch.clamp(dyn, min=free), weight)
        rep_l = masked_mean(torch.clamp(rep, min=free), weight)
    loss = dyn_scale * dyn_l + rep_scale * rep_l
    return loss, masked_mean(dyn.detach(), weight), masked_mean(rep.detach(), weight)
