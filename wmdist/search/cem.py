"""Batched cross-entropy method (CEM) over action sequences (PlaNet, docs/reference.md).

For each of E rows (environments), keep a diagonal Gaussian over H-step action sequences
[H, A]. Every iteration draws J candidates, clips them to the row's action bounds, scores
them with `score_fn` and refits mean and std to the K best (population std). The plan is
the final mean; its first step is the action (PlaNet's Algorithm 2).

The model comes in as a callable: `score_fn(actions [E, J, H, A]) -> scores [E, J]`,
higher is better. PlaNet's scores the sum of predicted rewards along a latent rollout of
each candidate; a goal-reaching planner scores minus the distance of the rollout's last
embedding to the goal embedding. The planner never mixes rows: sampling, clipping, top-K
and refitting are all per row, so a row's plan depends only on its own model, bounds,
initial mean and its slice of the random draws.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from wmdist.config.fields import MAX_HORIZON, MAX_PER_DECISION, param

ScoreFn = Callable[[torch.Tensor], torch.Tensor]  # actions [E, J, H, A] -> scores [E, J], higher is better


@dataclass
class CEMConfig:
    """One CEM planning call (defaults: PlaNet's planner, docs/reference.md)."""

    horizon: int = param(12, "planning horizon H (steps of each candidate action sequence)", ge=1, le=MAX_HORIZON)
    candidates: int = param(1000, "candidate action sequences J drawn per iteration", ge=1, le=MAX_PER_DECISION)
    top_k: int = param(100, "best candidates K the Gaussian is refit to", ge=1)
    iterations: int = param(10, "refits I per decision", ge=1, le=MAX_HORIZON)
    init_std: float = param(1.0, "std of the initial Gaussian, in model action units ([-1, 1] bounds)", gt=0)
    warm_start: bool = param(False, "start from the previous decision's plan shifted by one step (PlaNet: a fresh N(0, 1))")

    def validate(self) -> None:
        """One-line ValueError for combinations the ranges alone can't catch."""
        if self.top_k > self.candidates:
            raise ValueError(f"planner.top_k ({self.top_k}) must not exceed planner.candidates ({self.candidates})")


@dataclass
class CEMResult:
    """What one planning call returns."""

    mean: torch.Tensor  # [E, H, A] the fitted plan
    std: torch.Tensor  # [E, H, A]
    elite_score: torch.Tensor  # [E] mean score of the last iteration's K best

    @property
    def action(self) -> torch.Tensor:
        """The plan's first action [E, A]."""
        return self.mean[:, 0]


def cem_plan(
    score_fn: ScoreFn,
    low: torch.Tensor,  # [E, A] lower action bound per row
    high: torch.Tensor,  # [E, A] upper action bound per row
    cfg: CEMConfig,
    generator: torch.Generator | None = None,
    init_mean: torch.Tensor | None = None,  # [E, H, A] warm start; None = the bounds' midpoint
) -> CEMResult:
    """Plan for E rows at once (see the module doc)."""
    cfg.validate()
    e, a_dim = low.shape
    h, j, k = cfg.horizon, cfg.candidates, cfg.top_k
    lo, hi = low[:, None, None, :], high[:, None, None, :]  # [E, 1, 1, A]
    mid = ((low + high) / 2)[:, None, :].expand(e, h, a_dim)  # [E, H, A]
    mean = (mid if init_mean is None else init_mean).clone()  # [E, H, A]
    std = torch.full_like(mean, cfg.init_std) * (high - low)[:, None, :] / 2  # init_std in [-1, 1] units
    elite_score = torch.zeros(e, device=low.device)
    for _ in range(cfg.iterations):
        eps = torch.randn((e, j, h, a_dim), generator=generator, device=low.device)  # [E, J, H, A]
        cand = torch.maximum(torch.minimum(mean[:, None] + std[:, None] * eps, hi), lo)
        score = score_fn(cand)  # [E, J]
        if score.shape != (e, j):
            raise ValueError(f"score_fn returned shape {tuple(score.shape)}, expected {(e, j)}")
        top, idx = score.topk(k, dim=1)  # [E, K]
        elite = cand.gather(1, idx[:, :, None, None].expand(e, k, h, a_dim))  # [E, K, H, A]
        mean = elite.mean(1)
        std = elite.std(1, unbiased=False) if k > 1 else torch.zeros_like(mean)
        elite_score = top.mean(1)
    return CEMResult(mean=mean, std=std, elite_score=elite_score)


def shift_plan(mean: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """A warm start for the next decision: the plan [E, H, A] advanced one step, its new last
    step at the bounds' midpoint [E, A]."""
    tail = ((low + high) / 2)[:, None, :]  # [E, 1, A]
    return torch.cat([mean[:, 1:], tail], 1)
