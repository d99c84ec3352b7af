"""Dreamer's acting policy: filters observations through the RSSM per env and queries the actor."""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from wmdist.algos.base import Policy, Weights
from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.nets.latent_layers import Latent
from wmdist.algos.dreamer.learner import load_policy_weights
from wmdist.algos.dreamer.nets import ActorCritic, WorldModel, action_to_env
from wmdist.nets.actions import action_to_model
from wmdist.envs.spec import EnvSpec


class DreamerPolicy(Policy):
    """Carries (h, z, previous action) for each of E envs; resets rows where `first`.

    Exploration samples the actor; V1 also adds N(0, expl_noise) to that sample (the authors'
    code: `actor(feat).sample()`, then additive Gaussian noise 0.3, clipped to [-1, 1]).
    Greedy (explore=False) takes the actor's mode.
    """

    def __init__(self, cfg: DreamerConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        self.wm = WorldModel(cfg, spec).to(self.device).eval()
        self.ac = ActorCritic(cfg, spec, self.wm.rssm.z_dim).to(self.device).eval()
        self.generator = torch.Generator(self.device).manual_seed(seed)
        self.version = -1
        self.env_steps = 0
        self.h: torch.Tensor | None = None  # [E, D]
        self.z: Latent | None = None
        self.prev_action: torch.Tensor | None = None  # [E, A] model space

    def set_weights(self, weights: Weights, version: int) -> None:
        load_policy_weights(self.wm, self.ac, weights)
        self.version = version

    def set_progress(self, env_steps: int, updates: int) -> None:
        self.env_steps = env_steps

    def reset(self, num_envs: int) -> None:
        self.h, self.z = self.wm.rssm.initial(num_envs, self.device)
        self.prev_action = torch.zeros(num_envs, self.spec.action_dim, device=self.device)

    @torch.no_grad()
    def act(self, obs, first, legal, to_play, explore):  # type: ignore[override]
        obs_t = torch.as_tensor(np.array(obs), device=self.device)
        e = obs_t.shape[0]
        if self.h is None or self.h.shape[0] != e:
            self.reset(e)
        assert self.h is not None and self.z is not None and self.prev_action is not None
        keep = torch.as_tensor(~np.asarray(first, bool), device=self.device).float().unsqueeze(-1)  # [E, 1]
        h, z = self.wm.filter_step(self.h, self.z, self.prev_action, obs_t, keep, self.generator)
        dist = self.ac.policy(h, z)
        if self.spec.discrete:
            if legal is not None:
                mask = torch.as_tensor(np.array(legal, bool), device=self.device)
                dist.logp = dist.logp.masked_fill(~mask, -torch.inf)
            action = dist.sample(self.generator) if explore else dist.mode()
            a_model = F.one_hot(action, self.spec.num_actions).float()
        else:
            action = dist.sample(self.generator) if explore else dist.mode()
            if explore and self.cfg.expl_noise > 0:  # V1: Gaussian noise around the actor's sample
                noise = torch.randn(action.shape, generator=self.generator, device=self.device)
                action = action + self.cfg.expl_noise * noise
            action = action.clamp(-1, 1)
            a_model = action
        self.h, self.z, self.prev_action = h, z, a_model
        return action_to_env(action, self.spec), {}

    def taken(self, actions: np.ndarray) -> None:
        """The warm-up's random actions replace the ones returned: the filter's next step sees them."""
        self.prev_action = action_to_model(torch.as_tensor(np.asarray(actions), device=self.device), self.spec)
