"""SIGReg (LeWorldModel, Maes et al. 2026; docs/reference.md#next-generation-world-models-jepa--leworldmodel):
a sliced Epps-Pulley test of the embeddings against the isotropic standard normal.

For each of M random unit directions u, the N embeddings are projected to x_n = <z_n, u>, and
the 1-D empirical characteristic function phi_N(t) = mean_n exp(i t x_n) is compared with the
standard normal's exp(-t^2 / 2):

    EP(u) = N * int_0^{t_max} |phi_N(t) - exp(-t^2/2)|^2 exp(-t^2/2) dt
          = N * int ((mean cos(t x) - exp(-t^2/2))^2 + (mean sin(t x))^2) exp(-t^2/2) dt

by the trapezoid rule on K evenly spaced knots (LeWM: M 1024, t in [0, 3], K 17), and
SIGReg = mean_u EP(u). It is O(1) for Gaussian samples and grows with N for collapsed or
anisotropic ones; it is differentiable in z, and its gradient spreads a collapsed batch
(the cos/sin means are pulled towards a Gaussian's), so no stop-gradient or EMA target is needed.
"""
from __future__ import annotations

import torch


def trapezoid_knots(knots: int, t_max: float, device: torch.device | str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    """Knots t [K] on [0, t_max] and their trapezoid weights w [K] (sum w = t_max)."""
    if knots < 2:
        raise ValueError(f"SIGReg needs at least 2 integration knots, got {knots}")
    t = torch.linspace(0.0, t_max, knots, device=device)
    w = torch.full((knots,), t_max / (knots - 1), device=device)
    w[0] = w[-1] = w[0] / 2
    return t, w


def random_directions(dim: int, num: int, generator: torch.Generator | None = None,
                      device: torch.device | str = "cpu") -> torch.Tensor:
    """M unit directions [D, M], uniform on the sphere."""
    u = torch.randn((dim, num), generator=generator, device=device)
    return u / u.norm(dim=0, keepdim=True)


def epps_pulley(x: torch.Tensor,  # [N, M] one column per projection
                t: torch.Tensor,  # [K] knots
                w: torch.Tensor,  # [K] quadrature weights
                ) -> torch.Tensor:
    """The Epps-Pulley statistic of each column against N(0, 1): [M]."""
    n = x.shape[0]
    tx = x[:, :, None] * t  # [N, M, K]
    gauss = torch.exp(-0.5 * t * t)  # [K] the standard normal's characteristic function (and the weight)
    err = (tx.cos().mean(0) - gauss) ** 2 + tx.sin().mean(0) ** 2  # [M, K]
    return n * (err * gauss) @ w  # [M]


def sigreg(z: torch.Tensor,  # [N, D] embeddings (one per row)
           directions: torch.Tensor,  # [D, M] unit directions
           knots: int = 17, t_max: float = 3.0) -> torch.Tensor:
    """SIGReg(z): the mean over directions of the Epps-Pulley statistic (a scalar)."""
    t, w = trapezoid_knots(knots, t_max, z.device)
    return epps_pulley(z @ directions, t.to(z.dtype), w.to(z.dtype)).mean()


def effective_rank(z: torch.Tensor) -> float:
    """exp(entropy of the normalised singular values) of the centred embeddings [N, D]
    (Roy & Vetterli 2007): D for isotropic ones, 1 for embeddings on a line, ~0 collapsed."""
    s = torch.linalg.svdvals((z - z.mean(0)).double())
    if float(s.sum()) <= 1e-12:
        return 0.0
    p = s / s.sum()
    p = p[p > 0]
    return float(torch.exp(-(p * p.log()).sum()))
