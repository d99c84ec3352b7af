"""Dreamer's acting policy: filters observations through the RSSM per env and queries the actor."""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from wmdist.algos.base import Weights
from wmdist.algos.filtering import FilteringPolicy
from wmdist.algos.greedy_share import greedy_rows
from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.algos.dreamer.learner import load_policy_weights
from wmdist.algos.dreamer.nets import ActorCritic, WorldModel, action_to_env
from wmdist.envs.spec import EnvSpec
from wmdist.nets.generator import seeded_generator


class DreamerPolicy(FilteringPolicy):
    """Carries (h, z, previous action) for each of E envs; resets rows where `first`.

    Exploration samples the actor; V1 also adds N(0, expl_noise) to that sample (the authors'
    code: `actor(feat).sample()`, then additive Gaussian noise 0.3, clipped to [-1, 1]).
    Greedy (explore=False) takes the actor's mode, as do the `greedy_fraction` share of envs when exploring.
    """

    def __init__(self, cfg: DreamerConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        self.wm = WorldModel(cfg, spec).to(self.device).eval()
        self.ac = ActorCritic(cfg, spec, self.wm.rssm.z_dim).to(self.device).eval()
        self.generator = seeded_generator(self.device, seed)
        self.version = -1
        self.env_steps = 0

    def set_weights(self, weights: Weights, version: int) -> None:
        load_policy_weights(self.wm, self.ac, weights)
        self.version = version

    def set_progress(self, env_steps: int, updates: int) -> None:
        self.env_steps = env_steps

    def _choose(self, dist, explore: bool, greedy: torch.Tensor | None) -> torch.Tensor:
        """The actor's sample (exploring) or mode; exploring, the `greedy` rows [E] bool (the
        `greedy_fraction` share of envs; None: none) take the mode, as the evaluator does."""
        if not explore:
            return dist.mode()
        action = dist.sample(self.generator)
        if greedy is not None:
            action[greedy] = dist.mode()[greedy]
        return action

    @torch.no_grad()
    def act(self, obs, first, legal, to_play, explore):  # type: ignore[override]
        h, z, _ = self.filter(obs, first)
        dist = self.ac.policy(h, z)
        greedy = None  # [E] bool rows that act on the mode while exploring
        if explore and self.cfg.greedy_fraction > 0:
            greedy = torch.as_tensor(greedy_rows(self.cfg.greedy_fraction, h.shape[0]), device=self.device)
        if self.spec.discrete:
            if legal is not None:
                mask = torch.as_tensor(np.array(legal, bool), device=self.device)
                dist.logp = dist.logp.masked_fill(~mask, -torch.inf)
            action = self._choose(dist, explore, greedy)
            a_model = F.one_hot(action, self.spec.num_actions).float()
        else:
            action = self._choose(dist, explore, greedy)
            if explore and self.cfg.expl_noise > 0:  # V1: Gaussian noise around the actor's sample
                noise = torch.randn(action.shape, generator=self.generator, device=self.device)
                if greedy is not None:
                    noise[greedy] = 0
                action = action + self.cfg.expl_noise * noise
            action = action.clamp(-1, 1)
            a_model = action
        self.h, self.z, self.prev_action = h, z, a_model
        return action_to_env(action, self.spec), {}
