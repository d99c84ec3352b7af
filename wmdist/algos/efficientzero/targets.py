"""EfficientZero's targets (numpy): value prefixes, the consistency mask and the
off-policy-corrected horizon (docs/reference.md, EfficientZero)."""
from __future__ import annotations

import numpy as np

from wmdist.algos.muzero.targets import episode_extent


def value_prefix_targets(reward: np.ndarray, horizon: int) -> np.ndarray:
    """[B, K+1] per-step reward targets (column 0 unused) -> [B, K+1] value prefixes: the sum
    of rewards since the last LSTM reset, which happens before step k where (k-1) % horizon == 0
    (the parent latent s^{k-1} sits at a depth that is a multiple of the horizon, as in the
    search). Rewards past a terminal are 0, so the prefix stays flat there."""
    out = np.zeros_like(reward, dtype=np.float32)
    k1 = reward.shape[1]
    for start in range(1, k1, horizon):  # one segment per reset
        stop = min(start + horizon, k1)
        out[:, start:stop] = np.cumsum(reward[:, start:stop], axis=1)
    return out


def consistency_mask(batch: dict[str, np.ndarray], t0: np.ndarray, valid: np.ndarray, unroll_steps: int) -> np.ndarray:
    """[B, K] float32: 1 where o_{t0+k} (k = 1..K) is a real observation of the same episode
    (a terminal's final observation included), 0 past the episode's end or the window's."""
    e, _, _ = episode_extent(batch, t0)
    pos = t0[:, None] + np.arange(1, unroll_steps + 1)[None, :]  # [B, K]
    return ((pos <= e[:, None]) & valid[:, None]).astype(np.float32)


def corrected_horizon(age: np.ndarray, n: int, tau: float) -> np.ndarray:
    """l = clip(n - floor(age / tau), 1, n) (int64, age's shape): fresh data keeps n steps of
    real rewards, data older than (n - 1) tau transitions gets 1 (docs/reference.md,
    EfficientZero: off-policy correction)."""
    if tau <= 0:
        raise ValueError(f"off-policy tau must be > 0, got {tau}")
    lost = np.floor(np.maximum(np.asarray(age, np.float64), 0.0) / tau).astype(np.int64)
    return np.clip(n - lost, 1, n).astype(np.int64)
