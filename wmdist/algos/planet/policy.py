"""PlaNet's acting policy: filter each env's observation through the RSSM, then plan with CEM
for all E envs at once (one batched planning call per step).

Collecting (explore=True) adds N(0, expl_noise) to the planned action (PlaNet: 0.3) and
clips it to the bounds; the evaluator (explore=False) takes the planned action as is.
Until the learner has published trained weights (version 0 is its initial snapshot) a
collector's plan would be arbitrary, so it acts uniformly at random instead, as in PlaNet's
seed episodes, and spends no time planning (the runtime asks for actions during its random
warm-up too); the posterior still follows every observation.
"""
from __future__ import annotations

import torch

from wmdist.algos.base import Weights
from wmdist.algos.filtering import FilteringPolicy
from wmdist.algos.planet.config import PlaNetConfig
from wmdist.algos.planet.planning import reward_sum_fn
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_env
from wmdist.nets.generator import seeded_generator
from wmdist.nets.world_model import WorldModel, load_world_model
from wmdist.search.cem import cem_plan, shift_plan


class PlaNetPolicy(FilteringPolicy):
    """Carries (h, z, previous action, previous plan) per env; resets rows where `first`."""

    def __init__(self, cfg: PlaNetConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        self.wm = WorldModel(cfg.world_model(), spec).to(self.device).eval()
        self.generator = seeded_generator(self.device, seed)
        self.version = -1
        self.plan: torch.Tensor | None = None  # [E, H, A] the last plan (warm start)

    def set_weights(self, weights: Weights, version: int) -> None:
        load_world_model(self.wm, weights)
        self.version = version

    def reset(self, num_envs: int) -> None:
        super().reset(num_envs)
        self.plan = None

    @torch.no_grad()
    def act(self, obs, first, legal, to_play, explore):  # type: ignore[override]
        h, z, restart = self.filter(obs, first)
        e = h.shape[0]
        a_dim, planner = self.spec.action_dim, self.cfg.planner
        if explore and self.version <= 0:  # an untrained model: a seed-episode action, no planning
            action = torch.rand((e, a_dim), generator=self.generator, device=self.device) * 2 - 1
            self.h, self.z, self.prev_action, self.plan = h, z, action, None
            return action_to_env(action, self.spec), {}
        low = torch.full((e, a_dim), -1.0, device=self.device)  # model space: every bound maps to [-1, 1]
        high = torch.ones_like(low)
        init = None
        if planner.warm_start and self.plan is not None:
            init = shift_plan(self.plan, low, high)
            init[restart] = 0.0  # a new episode starts from the fresh Gaussian
        result = cem_plan(reward_sum_fn(self.wm, h, z, self.generator), low, high, planner, self.generator, init)
        action = result.action  # [E, A]
        if explore and self.cfg.expl_noise > 0:
            noise = torch.randn(action.shape, generator=self.generator, device=self.device)
            action = (action + self.cfg.expl_noise * noise).clamp(-1, 1)
        self.h, self.z, self.prev_action, self.plan = h, z, action, result.mean
        return action_to_env(action, self.spec), {}
