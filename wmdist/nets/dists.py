"""Distributions and transforms used by world models (DreamerV3 numbers in docs/reference.md).

symlog/symexp squash targets of unknown scale; two-hot spreads a scalar over two adjacent
bins of a fixed support; categorical latents are sampled as one-hots with straight-through
gradients and (V3) a uniform mix that keeps every class probability above mix/C.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F


def symlog(x: torch.Tensor) -> torch.Tensor:
    """DreamerV3 eq. 9: sign(x) ln(|x| + 1)."""
    return torch.sign(x) * torch.log1p(torch.abs(x))


def symexp(x: torch.Tensor) -> torch.Tensor:
    """Inverse of symlog: sign(x) (exp(|x|) - 1)."""
    return torch.sign(x) * torch.expm1(torch.abs(x))


def twohot_bins(num_bins: int = 255, low: float = -20.0, high: float = 20.0) -> torch.Tensor:
    """Evenly spaced bin centres in symlog space (V3: 255 bins on [-20, 20])."""
    if num_bins < 2 or not low < high:
        raise ValueError(f"two-hot needs >= 2 bins and low < high, got {num_bins} on [{low}, {high}]")
    # computed in float64 so the centre bin is exactly 0 for symmetric supports
    k = torch.arange(num_bins, dtype=torch.float64)
    return ((low * (num_bins - 1 - k) + high * k) / (num_bins - 1)).float()


def twohot_encode(y: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    """Two-hot target for values y already in bin space: [...] -> [..., K] (DreamerV3 eq. 10).

    Weight on the two bins enclosing y is linear in the distance to each; outside the
    support all mass goes to the end bin.
    """
    y = y.float().clamp(bins[0], bins[-1])
    k = torch.bucketize(y, bins, right=True).clamp(1, len(bins) - 1)  # index of the upper bin
    lo, hi = bins[k - 1], bins[k]
    w_hi = (y - lo) / (hi - lo)
    out = torch.zeros(*y.shape, len(bins), dtype=torch.float32, device=y.device)
    out.scatter_(-1, (k - 1).unsqueeze(-1), (1 - w_hi).unsqueeze(-1))
    out.scatter_add_(-1, k.unsqueeze(-1), w_hi.unsqueeze(-1))
    return out


def twohot_nll(logp: torch.Tensor, y: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    """-log-likelihood of two-hot(symlog(y)) under log-probs [..., K]; returns [...].

    Reads only the two bins that carry the target's mass (a gather), instead of building
    the dense [..., K] target and a K-wide product: same value as
    `-(twohot_encode(symlog(y), bins) * logp).sum(-1)`.
    """
    v = symlog(y.float()).clamp(bins[0], bins[-1])
    k = torch.bucketize(v, bins, right=True).clamp(1, len(bins) - 1).unsqueeze(-1)  # upper bin [..., 1]
    lo, hi = bins[k - 1], bins[k]
    w_hi = (v.unsqueeze(-1) - lo) / (hi - lo)
    pair = torch.cat([logp.gather(-1, k - 1), logp.gather(-1, k)], -1)  # [..., 2]
    return -(pair[..., 0] * (1 - w_hi[..., 0]) + pair[..., 1] * w_hi[..., 0])


def twohot_loss(logits: torch.Tensor, y: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    """Cross-entropy of logits [..., K] against two-hot(symlog(y)); returns [...]."""
    return twohot_nll(F.log_softmax(logits.float(), -1), y, bins)


def twohot_mean(logits: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    """Expected value under the bin distribution, mapped back with symexp: [..., K] -> [...]."""
    return symexp((F.softmax(logits.float(), -1) * bins).sum(-1))  # (measured: faster than `@ bins` here)


def unimix_logits(logits: torch.Tensor, mix: float) -> torch.Tensor:
    """Log-probabilities of (1 - mix) softmax(logits) + mix / C over the last axis (V3: 1%)."""
    if mix <= 0:
        return F.log_softmax(logits.float(), -1)
    probs = F.softmax(logits.float(), -1)
    probs = (1 - mix) * probs + mix / logits.shape[-1]
    return torch.log(probs)


def rand_as(x: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Uniform [0, 1) float32 draws shaped and placed like `x`.

    Without a generator it is `rand_like`: compiled code whose batch size is symbolic cannot pass a
    shape to `torch.rand` (and draws the same values from the global RNG as `torch.rand(x.shape)`)."""
    if generator is None:
        return torch.rand_like(x, dtype=torch.float32, memory_format=torch.contiguous_format)
    return torch.rand(x.shape, generator=generator, device=x.device)


def randn_as(x: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Standard normal float32 draws shaped and placed like `x` (`randn_like` without a generator, as `rand_as`)."""
    if generator is None:
        return torch.randn_like(x, dtype=torch.float32, memory_format=torch.contiguous_format)
    return torch.randn(x.shape, generator=generator, device=x.device)


def sample_onehot_index(logp: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Sample class indices from log-probabilities [..., C] with the Gumbel-max trick -> [...]."""
    u = rand_as(logp, generator).clamp_(1e-20, 1.0)
    return torch.argmax(logp - torch.log(-torch.log(u)), -1)


def sample_index_from_probs(probs: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Sample class indices from probabilities [..., C] by inverting the CDF -> [...].

    One uniform per variable and no logarithms (cheaper than Gumbel-max for 32x32 latents).
    """
    cdf = probs.detach().float().cumsum(-1)
    u = rand_as(cdf[..., -1:], generator) * cdf[..., -1:]
    return (cdf < u).sum(-1).clamp_(max=probs.shape[-1] - 1)


def straight_through_onehot(index: torch.Tensor, probs: torch.Tensor) -> torch.Tensor:
    """One-hot of `index` whose gradient flows to `probs` [..., C] (DreamerV2 eq. straight-through)."""
    onehot = F.one_hot(index, probs.shape[-1]).to(probs.dtype)
    return onehot + probs - probs.detach()


def categorical_kl(logp: torch.Tensor, logq: torch.Tensor) -> torch.Tensor:
    """KL(p || q) for log-probabilities [..., S, C], summed over the S variables -> [...]."""
    return (logp.exp() * (logp - logq)).sum((-1, -2))


def gaussian_kl(mean_p: torch.Tensor, std_p: torch.Tensor, mean_q: torch.Tensor, std_q: torch.Tensor) -> torch.Tensor:
    """KL(N(mp, sp) || N(mq, sq)) of diagonal Gaussians [..., Z], summed over Z -> [...]."""
    var_p, var_q = std_p.pow(2), std_q.pow(2)
    kl = torch.log(std_q / std_p) + (var_p + (mean_p - mean_q).pow(2)) / (2 * var_q) - 0.5
    return kl.sum(-1)


def bernoulli_nll(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """-log p(target) for Bernoulli logits (continue head)."""
    return F.binary_cross_entropy_with_logits(logits.float(), target.float(), reduction="none")
