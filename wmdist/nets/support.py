"""MuZero's value/reward transform h(x) and the categorical "support" encoding of scalars.

Scalars are squashed with h (Pohlen et al., 2018; MuZero Appendix F), then written as a
two-hot distribution over the integers [-S, S]: 3.7 -> 0.3 on 3 and 0.7 on 4. Networks
predict logits over those 2S + 1 atoms; the expected atom, mapped back by h^-1, is the scalar.
"""
from __future__ import annotations

import torch

H_EPS = 1e-3  # MuZero's epsilon in h(x)


def h(x: torch.Tensor, eps: float = H_EPS) -> torch.Tensor:
    """h(x) = sign(x) (sqrt(|x| + 1) - 1) + eps x."""
    return torch.sign(x) * (torch.sqrt(torch.abs(x) + 1.0) - 1.0) + eps * x


def h_inv(y: torch.Tensor, eps: float = H_EPS) -> torch.Tensor:
    """Exact inverse of `h` (solve the quadratic in sqrt(|x| + 1))."""
    root = (torch.sqrt(1.0 + 4.0 * eps * (torch.abs(y) + 1.0 + eps)) - 1.0) / (2.0 * eps)
    return torch.sign(y) * (root * root - 1.0)


def two_hot(y: torch.Tensor, support: int) -> torch.Tensor:
    """[...] already-transformed scalars -> [..., 2*support+1] weights on the integers [-S, S].

    Values outside [-S, S] are clipped to the end atoms.
    """
    if support < 1:
        raise ValueError(f"support must be >= 1, got {support}")
    y = y.clamp(-support, support)
    low = torch.floor(y)
    frac = y - low  # weight of the upper atom
    # NaN stays in the weights (the loss turns NaN and is refused) but never in an index.
    low_idx = (torch.nan_to_num(low, nan=-support) + support).long()  # [...]
    high_idx = (low_idx + 1).clamp(max=2 * support)
    out = torch.zeros(*y.shape, 2 * support + 1, dtype=y.dtype, device=y.device)
    out.scatter_add_(-1, low_idx.unsqueeze(-1), (1.0 - frac).unsqueeze(-1))
    out.scatter_add_(-1, high_idx.unsqueeze(-1), frac.unsqueeze(-1))
    return out


def scalar_to_support(x: torch.Tensor, support: int, eps: float = H_EPS) -> torch.Tensor:
    """[...] raw scalars -> [..., 2S+1] two-hot target of h(x)."""
    return two_hot(h(x, eps), support)


def support_to_scalar(logits: torch.Tensor, support: int, eps: float = H_EPS) -> torch.Tensor:
    """[..., 2S+1] logits -> [...] scalars: h^-1 of the expected atom under softmax(logits)."""
    if logits.shape[-1] != 2 * support + 1:
        raise ValueError(f"logits have {logits.shape[-1]} atoms, expected {2 * support + 1} for support {support}")
    atoms = torch.arange(-support, support + 1, dtype=logits.dtype, device=logits.device)
    expected = (torch.softmax(logits, dim=-1) * atoms).sum(-1)
    return h_inv(expected, eps)
