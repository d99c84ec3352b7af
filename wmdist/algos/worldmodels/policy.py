"""Collectors' and the evaluator's policy: random until the controller search has a best
candidate, then C on [z_t, h_t] with V's mean latent and M's LSTM state per env."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Policy, Weights
from wmdist.algos.worldmodels.config import WorldModelsConfig
from wmdist.algos.worldmodels.controller import act_batched
from wmdist.algos.worldmodels.models import build_rnn, build_vae, load_numpy
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_env, action_to_model


class WorldModelsPolicy(Policy):
    def __init__(self, cfg: WorldModelsConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        self.rng = np.random.default_rng(seed)
        self.vae = build_vae(cfg, spec).to(self.device).eval()
        self.rnn = build_rnn(cfg, spec).to(self.device).eval()
        self.controller: torch.Tensor | None = None  # [P], None while acting at random
        self.state: tuple[torch.Tensor, torch.Tensor] | None = None  # M's (h, c) [1, E, H]
        self.last_random: np.ndarray | None = None  # [E] or [E, A]: each env's last random action
        self.random_episode: np.ndarray | None = None  # [E] bool: this episode is played at random (collect_random)

    def set_weights(self, weights: Weights, version: int) -> None:
        load_numpy(self.vae, weights, "vae")
        load_numpy(self.rnn, weights, "rnn")
        if float(weights["has_controller"]) > 0:
            self.controller = torch.as_tensor(np.asarray(weights["controller"], np.float32), device=self.device)

    def _random(self, e: int, first: np.ndarray) -> np.ndarray:
        """Random play: [E] indices or [E, A] env actions; with `random_keep` each env repeats its last
        random action with that probability (never across an episode's start)."""
        s = self.spec
        if s.discrete:
            fresh = self.rng.integers(0, s.num_actions, size=e)
        else:
            fresh = self.rng.uniform(s.action_low, s.action_high, size=(e, *s.action_shape)).astype(np.float32)
        if self.cfg.random_keep > 0 and self.last_random is not None and len(self.last_random) == e:
            keep = (self.rng.random(e) < self.cfg.random_keep) & ~np.asarray(first, bool)  # [E]
            fresh = np.where(keep.reshape(-1, *([1] * (fresh.ndim - 1))), self.last_random, fresh)
        self.last_random = fresh
        return fresh

    @torch.no_grad()
    def act(self, obs, first, legal, to_play, explore):
        e = obs.shape[0]
        if self.controller is None:
            return self._random(e, first), {}
        if self.state is None or self.state[0].shape[1] != e:
            self.state = self.rnn.initial(e, self.device)
        keep = torch.as_tensor(~np.asarray(first, bool), device=self.device).float()[None, :, None]  # [1, E, 1]
        self.state = (self.state[0] * keep, self.state[1] * keep)  # a new episode starts from zero state
        mu, _ = self.vae.encode(torch.as_tensor(np.array(obs), device=self.device))  # [E, Z] (a copy: obs may be read-only)
        a = act_batched(self.controller[None], mu[None], self.state[0][0][None], self.spec)[0]  # [E] or [E, A]
        c = self.cfg
        rand = self._random(e, first) if explore and (c.collect_random > 0 or c.collect_noise > 0) else None  # env actions
        if explore and c.collect_noise > 0:
            if self.spec.discrete:
                flip = torch.as_tensor(self.rng.random(e) < c.collect_noise, device=self.device)
                a = torch.where(flip, torch.as_tensor(rand, device=self.device), a)
            else:
                a = (a + c.collect_noise * torch.as_tensor(self.rng.standard_normal(a.shape), device=self.device,
                                                           dtype=a.dtype)).clamp(-1, 1)
        env_a = action_to_env(a, self.spec)
        if explore and c.collect_random > 0:  # whole episodes of random play keep M's first data in replay
            fresh = np.asarray(first, bool)
            if self.random_episode is None or len(self.random_episode) != e:
                self.random_episode, fresh = np.zeros(e, bool), np.ones(e, bool)
            draw = self.rng.random(e) < c.collect_random  # [E]
            self.random_episode = np.where(fresh, draw, self.random_episode)
            env_a = np.where(self.random_episode.reshape(-1, *([1] * (np.ndim(env_a) - 1))), rand, env_a)
        _, _, _, _, self.state = self.rnn.step(mu, action_to_model(torch.as_tensor(env_a, device=self.device), self.spec),
                                               self.state)
        return env_a, {}
