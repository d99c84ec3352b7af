"""Latent overshooting (PlaNet, Hafner et al. 2019, eq. 7): the KL between the posterior
at t and the priors predicted d = 2..D steps earlier, p(s_t | s_{t-d}, a_{t-d:t-1}).

Each multi-step prior starts from the posterior sample at t - d and rolls the transition
forward open-loop with the real actions, sampling z from the prior at every step. The
posterior target is stop-gradient (PlaNet: the multi-step predictions are trained towards
the posterior, not the other way round). A (start, d) pair counts only when no episode
starts in (t - d, t] and step t is real (weight > 0). Free nats clip each distance's mean:

    L_os = beta * mean_{d=2..D} max(free, sum_{b,t} w_{b,t} KL_d(b, t) / sum w)

All starts of a batch move together: step d updates the [B, T - d] states that have a
target d steps ahead, so the cost is about D times one `observe` pass.
"""
from __future__ import annotations

import torch

from wmdist.nets.latent_layers import Latent
from wmdist.nets.rssm import RSSM


def overshooting_kl(
    rssm: RSSM,
    deter: torch.Tensor,  # [B, T, D] posterior-step deterministic states (from `observe`)
    latent: Latent,  # [B*T] posterior samples (from `observe`)
    post: torch.Tensor,  # [B, T, stats] posterior stats
    action: torch.Tensor,  # [B, T, A] model-space actions; action[t] is taken at o_t
    first: torch.Tensor,  # [B, T] bool
    weight: torch.Tensor,  # [B, T] mask (x importance weight)
    distance: int,  # D >= 2
    free: float,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Returns (L_os / beta, the mean KL over every counted pair before clipping, for logging)."""
    b, t_len = first.shape
    z = latent.sample
    assert z is not None, "latent overshooting needs a Gaussian latent"
    z = z.reshape(b, t_len, -1)  # [B, T, Z]
    target = post.detach()
    starts = torch.cumsum(first.long(), 1)  # [B, T] episode index: no reset in (s, t] iff equal at s and t
    a_part = rssm.action_part(action)  # [B, T, U] a_t's share of the transition input
    h = deter
    terms, total, count = [], torch.zeros((), device=deter.device), torch.zeros((), device=deter.device)
    last = min(distance, t_len - 1)
    for d in range(1, last + 1):
        rows = t_len - d  # starts s = 0 .. T-d-1 have a target at s + d
        h = rssm.img_step(h[:, :rows], Latent(sample=z[:, :rows]), a_part[:, d - 1:d - 1 + rows])  # [B, rows, D]
        prior = rssm.prior(h)  # p(s_{s+d} | s_s, a_{s:s+d-1}) [B, rows, stats]
        if d >= 2:
            valid = (starts[:, d:] == starts[:, :rows]).float() * weight[:, d:]  # [B, rows]
            kl = rssm.kl(target[:, d:], prior)  # [B, rows]
            mean = (kl * valid).sum() / valid.sum().clamp(min=1.0)
            terms.append(torch.clamp(mean, min=free))
            total, count = total + (kl.detach() * valid).sum(), count + valid.sum()
        if d < last:
            z = rssm.sample(prior, generator).sample  # z ~ p(. | h): the next step's input [B, rows, Z]
    if not terms:
        zero = torch.zeros((), device=deter.device)
        return zero, zero
    return torch.stack(terms).mean(), total / count.clamp(min=1.0)
