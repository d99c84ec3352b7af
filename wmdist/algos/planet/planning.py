"""PlaNet's CEM objective: the sum of predicted rewards along latent rollouts (Algorithm 2).

Each candidate action sequence of each env is rolled forward from that env's current
posterior state with the prior (sampled, as in the paper's planner); the reward head scores
every imagined state s_{t+1..t+H}. The planner in `wmdist.search.cem` only sees the callable.
"""
from __future__ import annotations

import torch

from wmdist.nets.latent_layers import Latent
from wmdist.nets.world_model import WorldModel
from wmdist.search.cem import ScoreFn


def reward_sum_fn(
    wm: WorldModel,
    h: torch.Tensor,  # [E, D] current deterministic states
    z: Latent,  # [E] current stochastic states (Gaussian)
    generator: torch.Generator | None = None,
) -> ScoreFn:
    """A score function actions [E, J, H, A] -> predicted return [E, J] from the states (h, z)."""
    rssm = wm.rssm
    assert z.sample is not None, "PlaNet plans with a Gaussian latent"

    @torch.no_grad()
    def score(actions: torch.Tensor) -> torch.Tensor:
        e, j, horizon, a_dim = actions.shape
        a_part = rssm.action_part(actions.reshape(e * j, horizon, a_dim))  # [E*J, H, U] in one matmul
        hs = h.repeat_interleave(j, 0)  # [E*J, D], candidates of one env are adjacent
        zs = Latent(sample=z.sample.repeat_interleave(j, 0))
        total = torch.zeros(e * j, device=h.device)
        for t in range(horizon):
            hs = rssm.img_step(hs, zs, a_part[:, t])
            zs = rssm.prior_sample(hs, generator, grad=False)
            total = total + wm.heads({"h": hs, "z": zs}, upto="reward")["reward"].float().squeeze(-1)
        return total.reshape(e, j)

    return score
