"""The actor's action distributions (model space: one-hot indices, or actions in [-1, 1]).

Discrete: categorical over logits with the V3 uniform mix. Continuous `normal` (V2/V3):
mean tanh(m), std in [min, max] via a sigmoid; `tanh_normal` (V1): tanh of a Gaussian with
mean 5 tanh(m / 5) and softplus std.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from wmdist.nets.dists import randn_as, sample_onehot_index, unimix_logits


def _softplus_inverse(y: float) -> float:
    """The raw offset that makes softplus(raw + offset) = y at raw = 0."""
    return math.log(math.expm1(y))


class ActionDist:
    """A batch of action distributions built from the actor head's output [N, A or 2A]."""

    def __init__(self, out: torch.Tensor, discrete: bool, kind: str, unimix: float, min_std: float, max_std: float,
                 init_std: float = 5.0) -> None:
        self.discrete, self.kind = discrete, kind
        out = out.float()
        if discrete:
            self.logp = unimix_logits(out, unimix)  # [N, A]
            return
        m, s = out.chunk(2, -1)
        if kind == "tanh_normal":
            self.mean = 5.0 * torch.tanh(m / 5.0)
            self.std = F.softplus(s + _softplus_inverse(init_std)) + min_std  # init_std + min_std at s = 0
        else:
            self.mean = torch.tanh(m)
            self.std = (max_std - min_std) * torch.sigmoid(s + 2.0) + min_std

    def sample(self, generator: torch.Generator | None = None) -> torch.Tensor:
        """Discrete: indices [N] (no gradient). Continuous: reparameterised actions [N, A] in [-1, 1]."""
        if self.discrete:
            return sample_onehot_index(self.logp.detach(), generator)
        eps = randn_as(self.mean, generator)
        x = self.mean + self.std * eps
        if self.kind == "tanh_normal":
            return torch.tanh(x)
        return x + (x.clamp(-1, 1) - x).detach()  # clip the value, keep the gradient

    def mode(self) -> torch.Tensor:
        if self.discrete:
            return self.logp.argmax(-1)
        return torch.tanh(self.mean) if self.kind == "tanh_normal" else self.mean

    def log_prob(self, action: torch.Tensor) -> torch.Tensor:
        """log pi(a) -> [N] for indices [N] or actions [N, A]."""
        if self.discrete:
            return self.logp.gather(-1, action.long().unsqueeze(-1)).squeeze(-1)
        if self.kind == "tanh_normal":
            a = action.clamp(-0.999999, 0.999999)
            u = torch.atanh(a)
            lp = torch.distributions.Normal(self.mean, self.std).log_prob(u) - torch.log1p(-a.pow(2))
            return lp.sum(-1)
        return torch.distributions.Normal(self.mean, self.std).log_prob(action).sum(-1)

    def entropy(self) -> torch.Tensor:
        """Entropy -> [N] (tanh_normal: that of the pre-tanh Gaussian, a common stand-in)."""
        if self.discrete:
            return -(self.logp.exp() * self.logp).sum(-1)
        return torch.distributions.Normal(self.mean, self.std).entropy().sum(-1)
