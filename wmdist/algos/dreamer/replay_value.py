"""DreamerV3's critic replay loss: the critic also regresses lambda-returns over replayed data.

Imagination alone teaches the critic only what the world model's continue head and its own
bootstrap say; real terminations (a cart leaving the track after 250 steps) reach it slowly.
The revised DreamerV3 (Hafner et al. 2023/2025, "critic replay loss", scale 0.3) also trains the
critic on the replay sequences: lambda-returns over the real rewards and terminations, with the
imagination returns R^lambda of the start states as the on-policy value annotations.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from wmdist.algos.dreamer.returns import lambda_returns
from wmdist.nets.latent_layers import Latent


@dataclass
class ReplayStates:
    """The posterior states of a replayed batch (detached) and what the data says about them."""

    deter: torch.Tensor  # [B*T, D]
    latent: Latent  # [B*T]
    reward: torch.Tensor  # [B, T] reward that arrived with o_t (0 at an episode's first step)
    terminal: torch.Tensor  # [B, T] bool: o_t ends its episode for good
    first: torch.Tensor  # [B, T] bool: o_t starts an episode
    weight: torch.Tensor  # [B, T] mask x importance weight (0 on padding)


def replay_lambda_returns(
    reward: torch.Tensor,  # [B, T]
    terminal: torch.Tensor,  # [B, T] bool
    first: torch.Tensor,  # [B, T] bool
    valid: torch.Tensor,  # [B, T] bool: a real step, not padding
    value: torch.Tensor,  # [B, T] value annotation v_t
    discount: float,
    lam: float,
) -> torch.Tensor:
    """R_t = r_{t+1} + gamma c_{t+1} ((1 - lam) v_{t+1} + lam R_{t+1}) where o_{t+1} follows o_t in
    the same episode, else R_t = v_t (the window's end, a truncation, a terminal) -> [B, T].

    The imagination's lambda-returns (DreamerV3 eq. 7, `returns.lambda_returns`) over the real
    steps, with c_{t+1} the real continue flag 1 - terminal_{t+1}. Where o_{t+1} does not follow
    o_t, a "reward" of v_t with continue 0 makes that step's return v_t.
    """
    follows = valid[:, 1:] & ~first[:, 1:] & valid[:, :-1]  # [B, T-1] o_{t+1} continues o_t's episode
    cont = discount * (1.0 - terminal[:, 1:].to(reward.dtype))  # [B, T-1] gamma c_{t+1}
    r = torch.where(follows, reward[:, 1:], value[:, :-1])
    c = torch.where(follows, cont, torch.zeros_like(cont))
    head = lambda_returns(r.T, c.T, value.T, lam).T  # [B, T-1]; the window's last step keeps v
    return torch.cat([head, value[:, -1:]], 1)
