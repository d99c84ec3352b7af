"""Data augmentation by the board's symmetries (board games only).

A rotated or reflected position is the same game, so a sample can be replaced by a random
symmetric copy: observation cells, unroll actions and policy targets move together, and
values and rewards are unchanged. AlphaGo Zero trained on the 8 dihedral copies of Go
positions; for tic-tac-toe it gives the learner 8x more distinct positions per game.
"""
from __future__ import annotations

import numpy as np


class Symmetries:
    """Built from `EnvSpec.symmetries`: (obs_perm, action_perm) pairs with
    obs'[obs_perm[i]] = obs[i] and a' = action_perm[a]."""

    def __init__(self, pairs: tuple) -> None:
        if not pairs:
            raise ValueError("augment_symmetries: this environment declares no symmetries")
        obs_perm = np.asarray([p[0] for p in pairs], np.int64)  # [G, D]
        self.act_perm = np.asarray([p[1] for p in pairs], np.int64)  # [G, A]
        self.obs_inv = np.argsort(obs_perm, axis=1)  # [G, D]: obs' = obs[obs_inv]
        self.act_inv = np.argsort(self.act_perm, axis=1)  # [G, A]: policy' = policy[act_inv]

    @property
    def size(self) -> int:
        return len(self.act_perm)

    def apply(self, g: np.ndarray, obs: np.ndarray, actions: np.ndarray,
              policy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Transform row b by symmetry g[b].

        g [B] int, obs [B, D] or [B, H, W, C] (permuted flattened), actions [B, K] int, policy [B, K+1, A]
        -> the transformed (obs, actions, policy), new arrays of the same shapes.
        """
        rows = np.arange(len(g))[:, None]
        flat = obs.reshape(len(g), -1)  # [B, D]
        obs_t = flat[rows, self.obs_inv[g]].reshape(obs.shape)
        actions_t = self.act_perm[g][rows, actions]  # [B, K]
        policy_t = np.take_along_axis(policy, self.act_inv[g][:, None, :], axis=2)  # [B, K+1, A]
        return obs_t, actions_t, policy_t
