"""Unroll targets for the MuZero loss from a batch of stored sequences (numpy, no torch).

For a start t0 and unroll positions p = t0 + k (k = 0..K), with E the last known index of
the episode inside the window (its last step if the episode ends there, else the window's
last real step):

- n-step value target (paper Eq. 4 / Appendix G):
      z_p = sum_{j=1..m} gamma^{j-1} r_{p+j} + gamma^m v_{p+m},   m = min(n, E - p)
  with no bootstrap when p + m is a terminal step (terminal states absorb: value 0);
  when p + m is a truncated last step, v comes from a network (it has no search value).
  Two-player games pass gamma = -discount: rewards are from the view of the player who
  moved and values from the player to move, so each ply flips the sign.
- reward target at k >= 1: r_p (the reward that arrived with o_p).
- policy target: the stored search policy where an action was taken at p.
- beyond a terminal: value 0 and reward 0 (weighted), policy unweighted;
  beyond a truncation or the window's end (the future is unknown): every weight 0.
Actions past the known data are uniform random (paper Appendix G).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class UnrollTargets:
    actions: np.ndarray  # [B, K] int64 actions fed to the dynamics
    reward: np.ndarray  # [B, K+1] float32 (column 0 unused)
    reward_w: np.ndarray  # [B, K+1] float32 loss weights (column 0 is 0)
    value_partial: np.ndarray  # [B, K+1] float32 discounted reward sum of z_p (before bootstrap)
    boot_idx: np.ndarray  # [B, K+1] int64 index into [T] of the bootstrap step, -1 for none
    boot_disc: np.ndarray  # [B, K+1] float32 gamma^m multiplying the bootstrap value
    boot_net: np.ndarray  # [B, K+1] bool: the bootstrap step has no search value (truncated last)
    value_w: np.ndarray  # [B, K+1] float32
    policy: np.ndarray  # [B, K+1, A] float32
    policy_w: np.ndarray  # [B, K+1] float32
    obs_idx: np.ndarray  # [B] int64 the start t0

    def value_target(self, boot_values: np.ndarray) -> np.ndarray:
        """[B, K+1] z given the values v at `boot_idx` ([B, K+1], ignored where boot_idx < 0)."""
        vb = np.where(self.boot_idx >= 0, boot_values, 0.0)
        return (self.value_partial + self.boot_disc * vb).astype(np.float32)


def acting_steps(mask: np.ndarray, last: np.ndarray) -> np.ndarray:
    """[B, T] bool: real steps where an action was taken (not a final observation)."""
    return mask.astype(bool) & ~last.astype(bool)


def sample_starts(mask: np.ndarray, last: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random start t0 [B] among each row's acting steps, and valid [B] (row has one)."""
    acting = acting_steps(mask, last)  # [B, T]
    counts = acting.sum(1)
    valid = counts > 0
    pick = np.floor(rng.random(len(counts)) * np.maximum(counts, 1)).astype(np.int64)  # k-th acting step
    cum = np.cumsum(acting, axis=1)  # [B, T]
    t0 = np.argmax(cum > pick[:, None], axis=1).astype(np.int64)
    return np.where(valid, t0, 0), valid


def episode_extent(batch: dict[str, np.ndarray], t0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(E [B], ended [B], terminal_end [B]) for rows starting at t0 (see the module doc)."""
    mask = batch["mask"].astype(bool)
    last = batch["last"].astype(bool) & mask
    first = batch["first"].astype(bool)
    b, t = mask.shape
    idx = np.arange(t)[None, :]
    after = idx >= t0[:, None]
    # The window stops being this episode at padding or at a new episode's first step.
    stop = after & (~mask | (first & (idx > t0[:, None])))
    window_end = np.where(stop.any(1), np.argmax(stop, 1), t)  # exclusive
    is_end = after & last & (idx < window_end[:, None])
    ended = is_end.any(1)
    end_idx = np.argmax(is_end, 1)
    e = np.where(ended, end_idx, window_end - 1).astype(np.int64)
    terminal_end = ended & batch["terminal"].astype(bool)[np.arange(b), end_idx]
    return e, ended, terminal_end


def make_targets(
    batch: dict[str, np.ndarray],
    t0: np.ndarray,  # [B] start indices (acting steps)
    valid: np.ndarray,  # [B] bool rows that have a start at all
    unroll_steps: int,
    td_steps: int | np.ndarray,  # n, or [B, 1] / [B, K+1] per-position n (EfficientZero's corrected horizon)
    gamma: float,  # discount; negative for alternating two-player games
    num_actions: int,
    rng: np.random.Generator,
) -> UnrollTargets:
    k1 = unroll_steps + 1
    reward_all = batch["reward"].astype(np.float32)  # [B, T]
    b, t = reward_all.shape
    rows = np.arange(b)[:, None]
    e, ended, term = episode_extent(batch, t0)
    pos = t0[:, None] + np.arange(k1)[None, :]  # [B, K+1]
    known = pos <= e[:, None]
    acting = known & ~((pos == e[:, None]) & ended[:, None]) & valid[:, None]
    absorbing = (pos > e[:, None]) & term[:, None] & valid[:, None]
    at_end = (pos == e[:, None]) & ended[:, None] & valid[:, None]

    # n-step returns for acting positions (Eq. 4); m = min(n, E - p) >= 1.
    m = np.minimum(td_steps, e[:, None] - pos)  # [B, K+1]
    partial = np.zeros((b, k1), np.float64)
    disc = np.ones((b, k1), np.float64)
    # m <= E - p <= T - 1: a td_steps past the window adds nothing (and 1e12 would never end)
    for j in range(1, min(int(np.max(td_steps, initial=1)), t - 1) + 1):
        use = acting & (j <= m)
        r = reward_all[rows, np.clip(pos + j, 0, t - 1)]
        partial += np.where(use, disc * r, 0.0)
        disc = np.where(use, disc * gamma, disc)
    boot = pos + m
    no_boot = ended[:, None] & term[:, None] & (boot == e[:, None])
    boot_idx = np.where(acting & ~no_boot, boot, -1).astype(np.int64)
    boot_net = (boot_idx >= 0) & ended[:, None] & (boot == e[:, None])  # truncated last step
    value_w = (acting | absorbing | (at_end & term[:, None])).astype(np.float32)
    partial = np.where(acting, partial, 0.0)

    reward = np.where(known & valid[:, None], reward_all[rows, np.clip(pos, 0, t - 1)], 0.0).astype(np.float32)
    reward_w = ((known | absorbing) & valid[:, None]).astype(np.float32)
    reward_w[:, 0] = 0.0
    reward[:, 0] = 0.0

    sp = batch["search_policy"].astype(np.float32)  # [B, T, A]
    policy = np.where(acting[..., None], sp[rows, np.clip(pos, 0, t - 1)], 0.0).astype(np.float32)
    policy_w = acting.astype(np.float32)

    stored_a = batch["action"].astype(np.int64)[rows, np.clip(pos[:, :-1], 0, t - 1)]  # [B, K]
    random_a = rng.integers(0, num_actions, size=stored_a.shape)
    actions = np.where(acting[:, :-1], stored_a, random_a).astype(np.int64)
    return UnrollTargets(
        actions=actions, reward=reward, reward_w=reward_w, value_partial=partial.astype(np.float32),
        boot_idx=boot_idx, boot_disc=np.where(boot_idx >= 0, disc, 0.0).astype(np.float32),
        boot_net=boot_net, value_w=value_w, policy=policy, policy_w=policy_w, obs_idx=t0,
    )
