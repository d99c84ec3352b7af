"""The acting side shared by world-model policies (Dreamer, PlaNet): each env's observation
is filtered through the RSSM into (h, z), conditioned on the previous action taken there."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Policy
from wmdist.nets.actions import action_to_model
from wmdist.nets.latent_layers import Latent


class FilteringPolicy(Policy):
    """Carries (h, z, previous action) for each of E envs; resets rows where `first`.
    Subclasses set `wm`, `spec`, `device` and `generator` before acting."""

    h: torch.Tensor | None = None  # [E, D]
    z: Latent | None = None
    prev_action: torch.Tensor | None = None  # [E, A] model space

    def reset(self, num_envs: int) -> None:
        self.h, self.z = self.wm.rssm.initial(num_envs, self.device)
        self.prev_action = torch.zeros(num_envs, self.spec.action_dim, device=self.device)

    def filter(self, obs: np.ndarray, first: np.ndarray) -> tuple[torch.Tensor, Latent, torch.Tensor]:
        """One posterior step for every env: (h [E, D], z, restart [E] bool). The caller stores
        h, z and the action it takes as the new state."""
        obs_t = torch.as_tensor(np.array(obs), device=self.device)
        if self.h is None or self.h.shape[0] != obs_t.shape[0]:
            self.reset(obs_t.shape[0])
        assert self.h is not None and self.z is not None and self.prev_action is not None
        restart = torch.as_tensor(np.asarray(first, bool), device=self.device)  # [E]
        keep = (~restart).float().unsqueeze(-1)  # [E, 1]
        h, z = self.wm.filter_step(self.h, self.z, self.prev_action, obs_t, keep, self.generator)
        return h, z, restart

    def taken(self, actions: np.ndarray) -> None:
        """The warm-up's random actions replace the ones returned: the filter's next step sees them."""
        self.prev_action = action_to_model(torch.as_tensor(np.asarray(actions), device=self.device), self.spec)
