"""EnvSpec: what an algorithm needs to know about an environment to build its networks."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EnvSpec:
    """Observation, action and player structure of an environment family instance.

    obs_shape: vector envs `(D,)`; image envs `(H, W, C)` channels-last (uint8 pixels).
    Discrete actions: `num_actions = n`, `action_shape = ()`, actions are int64 indices.
    Continuous actions: `num_actions = 0`, `action_shape = (D,)`, actions float32 in
    `[action_low, action_high]`.
    players: 1, or 2 for alternating zero-sum games (observations are from the view of
    the player to move; `to_play` and a legal-action mask come with every step).
    """

    id: str
    obs_shape: tuple[int, ...]
    obs_dtype: str  # numpy dtype name: "float32" or "uint8"
    obs_kind: str  # "vector" or "image"
    num_actions: int = 0  # discrete n; 0 for continuous
    action_shape: tuple[int, ...] = ()
    action_low: tuple[float, ...] = ()
    action_high: tuple[float, ...] = ()
    players: int = 1
    max_episode_steps: int | None = None
    # Board games: (obs_perm, action_perm) pairs, identity first; obs'[obs_perm[i]] = obs[i]
    # and a' = action_perm[a] give an equivalent position (for data augmentation).
    symmetries: tuple = ()

    @property
    def discrete(self) -> bool:
        return self.num_actions > 0

    @property
    def action_dtype(self) -> np.dtype:
        return np.dtype(np.int64) if self.discrete else np.dtype(np.float32)

    @property
    def action_dim(self) -> int:
        """Width of the action as a network input: n for discrete (one-hot), D for continuous."""
        return self.num_actions if self.discrete else math.prod(self.action_shape)  # math, not numpy: traceable
