"""M: the MDN-RNN (World Models, sec. 2.2): an LSTM over [z_t, a_t] whose output is, for
each latent dimension, a mixture of K Gaussians over z_{t+1}, plus a done head.

    P(z_{t+1} | a_t, z_t, h_t) = prod_d sum_k pi_{d,k} N(z_{t+1,d}; mu_{d,k}, sigma_{d,k}^2)

Sampling at temperature tau (the authors' code, docs/reference.md#world-models): the
mixture weights become softmax(log pi / tau) and every sigma is scaled by sqrt(tau); tau = 1
is the fitted model, tau > 1 a harder, more uncertain dream.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)


class MDNRNN(nn.Module):
    def __init__(self, z_dim: int, action_dim: int, hidden: int = 256, mixtures: int = 5) -> None:
        super().__init__()
        self.z_dim, self.action_dim, self.hidden, self.mixtures = z_dim, action_dim, hidden, mixtures
        self.lstm = nn.LSTM(z_dim + action_dim, hidden, batch_first=True)
        self.mdn = nn.Linear(hidden, z_dim * mixtures * 3)  # per (dim, component): log pi, mu, log sigma
        self.done = nn.Linear(hidden, 1)  # logit that z_{t+1} ends the episode

    def initial(self, batch: int, device: torch.device | str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
        """Zero (h, c), each [1, B, H]."""
        zero = torch.zeros(1, batch, self.hidden, device=device)
        return zero, zero.clone()

    def heads(self, out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """LSTM outputs [..., H] -> log pi, mu, log sigma [..., Z, K] and the done logit [...]."""
        p = self.mdn(out).unflatten(-1, (self.z_dim, self.mixtures, 3))
        log_pi = F.log_softmax(p[..., 0], -1)
        log_sigma = p[..., 2].clamp(-7.0, 5.0)  # keeps exp(.) finite while the model is young
        return log_pi, p[..., 1], log_sigma, self.done(out).squeeze(-1)

    def forward(self, z: torch.Tensor, action: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None):
        """z [B, T, Z], action [B, T, A] -> (log pi, mu, log sigma [B, T, Z, K], done logit [B, T], state)."""
        out, state = self.lstm(torch.cat([z, action], -1), state)
        return (*self.heads(out), state)

    def step(self, z: torch.Tensor, action: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor]):
        """One step for a batch: z [B, Z], action [B, A] -> heads [B, Z, K], done [B], state."""
        out, state = self.lstm(torch.cat([z, action], -1)[:, None], state)
        return (*self.heads(out[:, 0]), state)


def mdn_log_prob(log_pi: torch.Tensor, mu: torch.Tensor, log_sigma: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """log sum_k pi_k N(target; mu_k, sigma_k^2) per dimension: [..., Z, K] and target [..., Z] -> [..., Z]."""
    x = target.unsqueeze(-1)
    log_n = -0.5 * ((x - mu) / log_sigma.exp()).pow(2) - log_sigma - LOG_SQRT_2PI
    return torch.logsumexp(log_pi + log_n, -1)


def tempered(log_pi: torch.Tensor, log_sigma: torch.Tensor, tau: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The mixture at temperature tau: weights softmax(log pi / tau), sigma * sqrt(tau)."""
    if tau <= 0:
        raise ValueError(f"temperature tau must be > 0, got {tau}")
    return F.log_softmax(log_pi / tau, -1), log_sigma + 0.5 * math.log(tau)


def mdn_sample(log_pi: torch.Tensor, mu: torch.Tensor, log_sigma: torch.Tensor, tau: float,
               generator: torch.Generator | None = None) -> torch.Tensor:
    """One draw per dimension from the tempered mixture: [..., Z, K] -> [..., Z]."""
    log_pi, log_sigma = tempered(log_pi, log_sigma, tau)
    # the component by inverse CDF: the first k whose cumulative weight exceeds u (cheaper than multinomial)
    u = torch.rand((*log_pi.shape[:-1], 1), generator=generator, device=log_pi.device, dtype=log_pi.dtype)
    k = (log_pi.exp().cumsum(-1) < u).sum(-1, keepdim=True).clamp(max=log_pi.shape[-1] - 1)  # [..., Z, 1]
    m = mu.gather(-1, k).squeeze(-1)
    s = log_sigma.gather(-1, k).squeeze(-1).exp()
    eps = torch.randn(m.shape, generator=generator, device=m.device, dtype=m.dtype)
    return m + s * eps
