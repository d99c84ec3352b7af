"""JEPA's CEM objective: minus the squared distance between the last predicted embedding and
the goal image's embedding (LeWorldModel's planning cost, docs/reference.md), or, with
`goal_cost: sum`, minus the sum of the squared distances of every predicted step.

The last-step cost only sees where a sequence ends, so every ordering of the same moves
scores alike and the first action (the one MPC takes) is left to the noise of the elites;
the sum prefers sequences that get there early, which pins the first action down.
With `goal_cost: min` the cost is the closest approach, min_k ||z_{t+k} - z_goal||^2: a plan
that passes the goal and drifts on is not blamed for the drift (MPC stops there anyway, as the
episode ends on success). Alone it scores a plan that reaches the goal at step 3 and one that
wanders there by step 20 alike, so `step_cost` (beta) adds beta x k to step k's distance before
the minimum: min_k (||z_{t+k} - z_goal||^2 + beta k), the earlier arrival wins.

Each candidate action sequence of each env is rolled forward with the predictor from that
env's last h embeddings (and the h - 1 actions between them); the planner in
`wmdist.search.cem` only sees the callable.
"""
from __future__ import annotations

import torch

from wmdist.algos.jepa.config import GOAL_COSTS
from wmdist.algos.jepa.model import JepaModel
from wmdist.search.cem import ScoreFn


def rollout(model: JepaModel,
            z_hist: torch.Tensor,  # [N, h, D] the last h embeddings, oldest first
            a_past: torch.Tensor,  # [N, h-1, A] the actions taken at all but the newest
            actions: torch.Tensor,  # [N, H, A] the actions to imagine
            ) -> torch.Tensor:
    """The predicted embeddings z_{t+1..t+H} [N, H, D]."""
    out = []
    for k in range(actions.shape[1]):
        a_win = torch.cat([a_past, actions[:, k:k + 1]], 1)  # [N, h, A]
        z_next = model.predict(z_hist, a_win)  # [N, D]
        out.append(z_next)
        z_hist = torch.cat([z_hist[:, 1:], z_next[:, None]], 1)
        a_past = a_win[:, 1:]
    return torch.stack(out, 1)


def goal_distance_fn(model: JepaModel,
                     z_hist: torch.Tensor,  # [E, h, D]
                     a_past: torch.Tensor,  # [E, h-1, A]
                     z_goal: torch.Tensor,  # [E, D] the goal image's embedding
                     cost: str = "last",  # "last": the last step's distance; "sum": every step's; "min": the nearest
                     step_cost: float = 0.0,  # "min" only: beta, added per imagined step before the minimum
                     ) -> ScoreFn:
    """A score function actions [E, J, H, A] -> -||z_{t+H} - z_goal||^2 (or -sum_k ||z_{t+k} - z_goal||^2, or
    -min_k (||z_{t+k} - z_goal||^2 + step_cost k)) [E, J]."""
    if cost not in GOAL_COSTS:
        raise ValueError(f"goal cost must be 'last', 'sum' or 'min', got {cost!r}")

    @torch.no_grad()
    def score(actions: torch.Tensor) -> torch.Tensor:
        e, j, horizon, a_dim = actions.shape
        rep = lambda x: x.repeat_interleave(j, 0)  # candidates of one env are adjacent  # noqa: E731
        z = rollout(model, rep(z_hist), rep(a_past), actions.reshape(e * j, horizon, a_dim))  # [E*J, H, D]
        dist = ((z - rep(z_goal)[:, None]) ** 2).sum(-1)  # [E*J, H]
        if cost == "last":
            per_plan = dist[:, -1]
        elif cost == "sum":
            per_plan = dist.sum(-1)
        else:
            steps = torch.arange(1, horizon + 1, device=dist.device, dtype=dist.dtype)  # [H]: k = 1..H
            per_plan = (dist + step_cost * steps).min(-1).values
        return -per_plan.reshape(e, j)

    return score
