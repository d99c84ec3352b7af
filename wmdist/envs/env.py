"""Env: the single-environment interface every family (gym, dmc, atari, board) implements.

Conventions:
- observations: vector envs float32 `(D,)`; image envs uint8 `(H, W, C)` channels-last;
- actions: discrete -> a Python/NumPy int in `[0, n)`; continuous -> float32 `(D,)` in
  `[spec.action_low, spec.action_high]` (values outside are clipped);
- `step` returns `(obs, reward, terminated, truncated)`: `terminated` is a true terminal
  state (no bootstrap), `truncated` a time limit; after either, call `reset()`;
- two-player games: `to_play()` is the player to move at the current obs and the reward
  is from the view of the player who just moved.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from wmdist.envs.spec import EnvSpec


class Env(ABC):
    """One environment instance. Subclasses set `self.spec` in `__init__`."""

    spec: EnvSpec

    @abstractmethod
    def reset(self, seed: int | None = None) -> np.ndarray:
        """Start an episode; `seed` reseeds the env (None continues its random stream)."""

    @abstractmethod
    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        """Advance one agent step: `(obs, reward, terminated, truncated)`."""

    def legal_actions(self) -> np.ndarray | None:
        """[A] bool mask of legal actions at the current obs; None for continuous actions."""
        if not self.spec.discrete:
            return None
        mask = getattr(self, "_all_legal", None)
        if mask is None or mask.shape[0] != self.spec.num_actions:
            mask = np.ones(self.spec.num_actions, dtype=bool)
            mask.flags.writeable = False  # shared between calls: callers must not write it
            self._all_legal = mask
        return mask

    def to_play(self) -> int:
        """Player to move at the current obs (always 0 for single-player envs)."""
        return 0

    @abstractmethod
    def render(self) -> np.ndarray:
        """An RGB frame `(H, W, 3)` uint8 of the current state (for videos)."""

    def close(self) -> None:
        """Release simulator resources (idempotent)."""

    def __enter__(self) -> "Env":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def check_discrete_action(action: Any, n: int) -> int:
    """An int in [0, n) from an int-like action, else a clear ValueError."""
    if isinstance(action, (int, np.integer)) and not isinstance(action, bool):
        i = int(action)  # fast path: called once per env step
        if not 0 <= i < n:
            raise ValueError(f"action {i} out of range [0, {n})")
        return i
    a = np.asarray(action)
    if a.ndim != 0 or not np.issubdtype(a.dtype, np.integer):
        if a.ndim == 0 and np.issubdtype(a.dtype, np.floating) and float(a).is_integer():
            a = a.astype(np.int64)
        else:
            raise ValueError(f"discrete action must be one int in [0, {n}), got {action!r}")
    i = int(a)
    if not 0 <= i < n:
        raise ValueError(f"action {i} out of range [0, {n})")
    return i


def check_continuous_action(action: Any, spec: EnvSpec) -> np.ndarray:
    """A float32 `spec.action_shape` array clipped to the bounds, else a clear ValueError."""
    a = np.asarray(action, dtype=np.float32)
    if a.shape != tuple(spec.action_shape):
        raise ValueError(f"continuous action must have shape {tuple(spec.action_shape)}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"continuous action has non-finite values: {a.tolist()}")
    return np.clip(a, np.asarray(spec.action_low, np.float32), np.asarray(spec.action_high, np.float32))
