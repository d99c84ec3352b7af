"""`carracing:CarRacing-v3`: gymnasium's Box2D car racing from image_size x image_size pixels.

World Models (Ha & Schmidhuber 2018, docs/reference.md#world-models) resize each 96x96 frame
to 64x64 and act with 3 continuous actions (steer in [-1, 1], gas and brake in [0, 1]); the
reward is -0.1 per frame plus 1000/N per track tile visited, an episode is at most 1000
frames (the registered cap). Needs gymnasium's box2d extra (`box2d`).
"""
from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_continuous_action
from wmdist.envs.resize import resize_square
from wmdist.envs.spec import EnvSpec

CARRACING_IDS = ("CarRacing-v3",)


def carracing_names() -> list[str]:
    return list(CARRACING_IDS)


class CarRacingEnv(Env):
    def __init__(self, cfg: EnvConfig, seed: int, name: str) -> None:
        self._repeat, self._side = cfg.action_repeat, cfg.image_size
        kwargs: dict[str, Any] = {}
        if cfg.time_limit:
            kwargs["max_episode_steps"] = cfg.time_limit * self._repeat
        try:
            self._env = gym.make(name, render_mode="rgb_array", **kwargs)
        except gym.error.DependencyNotInstalled as e:
            raise ValueError(f"carracing:{name} needs box2d (pip install box2d): {str(e).splitlines()[0]}") from None
        self._seed: int | None = int(seed)
        act = self._env.action_space
        registered = self._env.spec.max_episode_steps if self._env.spec else None
        self.spec = EnvSpec(
            id=f"carracing:{name}", obs_shape=(self._side, self._side, 3), obs_dtype="uint8", obs_kind="image",
            action_shape=tuple(act.shape), action_low=tuple(float(x) for x in act.low),
            action_high=tuple(float(x) for x in act.high),
            max_episode_steps=cfg.max_steps(math.ceil(registered / self._repeat) if registered else None),
        )
        self._last: np.ndarray | None = None

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is None and self._seed is not None:
            seed = self._seed  # the construction seed starts the first episode
        self._seed = None
        obs, _ = self._env.reset(seed=seed)
        self._last = np.asarray(obs, np.uint8)
        return resize_square(self._last, self._side)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = check_continuous_action(action, self.spec)
        total, terminated, truncated = 0.0, False, False
        for _ in range(self._repeat):
            obs, reward, terminated, truncated, _ = self._env.step(a)
            total += float(reward)
            if terminated or truncated:
                break
        self._last = np.asarray(obs, np.uint8)
        return resize_square(self._last, self._side), total, bool(terminated), bool(truncated)

    def render(self) -> np.ndarray:
        if self._last is None:
            raise RuntimeError("carracing: render before reset")
        return self._last.copy()  # the full 96x96 frame

    def close(self) -> None:
        self._env.close()
