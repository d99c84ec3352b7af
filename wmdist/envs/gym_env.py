"""`gym:<id>`: any gymnasium environment behind the wmdist `Env` interface.

Box observations become float32 vectors (flattened) or, for uint8 images, `(H, W, C)`
channels-last; a Discrete observation becomes a one-hot float32 vector. Discrete and
Box action spaces are supported.
"""
from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_continuous_action, check_discrete_action
from wmdist.envs.spec import EnvSpec


class GymEnv(Env):
    """A gymnasium env with action repeat and an optional step cap in agent steps."""

    def __init__(self, cfg: EnvConfig, seed: int, gym_id: str) -> None:
        self._repeat = cfg.action_repeat
        kwargs: dict[str, Any] = {}
        if cfg.time_limit:
            # Replace the registered TimeLimit (counted in raw env steps).
            kwargs["max_episode_steps"] = cfg.time_limit * self._repeat
        try:
            self._env = gym.make(gym_id, render_mode="rgb_array", **kwargs)
        except gym.error.DependencyNotInstalled as e:
            raise ValueError(f"gym:{gym_id} needs an extra package: {str(e).splitlines()[0]}") from None
        self._seed: int | None = int(seed)
        try:
            self._build_spec(cfg, gym_id)
        except BaseException:
            self._env.close()
            raise

    def _build_spec(self, cfg: EnvConfig, gym_id: str) -> None:
        self._obs_fn, obs_shape, obs_dtype, obs_kind = _obs_adapter(gym_id, self._env.observation_space)
        act = self._env.action_space
        registered = self._env.spec.max_episode_steps if self._env.spec else None
        max_steps = math.ceil(registered / self._repeat) if registered else None
        common = dict(
            id=f"gym:{gym_id}", obs_shape=obs_shape, obs_dtype=obs_dtype, obs_kind=obs_kind,
            max_episode_steps=cfg.max_steps(max_steps),
        )
        if isinstance(act, gym.spaces.Discrete):
            self._act_start = int(act.start)
            self.spec = EnvSpec(num_actions=int(act.n), **common)
        elif isinstance(act, gym.spaces.Box) and len(act.shape) == 1:
            self.spec = EnvSpec(
                action_shape=tuple(act.shape),
                action_low=tuple(float(x) for x in act.low.ravel()),
                action_high=tuple(float(x) for x in act.high.ravel()),
                **common,
            )
        else:
            raise ValueError(f"gym:{gym_id}: unsupported action space {act}")

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is None and self._seed is not None:
            seed = self._seed  # the construction seed starts the first episode
        self._seed = None
        if seed is not None:
            self._env.action_space.seed(seed)
        obs, _ = self._env.reset(seed=seed)
        return self._obs_fn(obs)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        if self.spec.discrete:
            a: Any = check_discrete_action(action, self.spec.num_actions) + self._act_start
        else:
            a = check_continuous_action(action, self.spec)
        total = 0.0
        for _ in range(self._repeat):
            obs, reward, terminated, truncated, _ = self._env.step(a)
            total += float(reward)
            if terminated or truncated:
                break
        return self._obs_fn(obs), total, bool(terminated), bool(truncated)

    def render(self) -> np.ndarray:
        try:
            frame = self._env.render()
        except gym.error.DependencyNotInstalled as e:
            raise RuntimeError(f"{self.spec.id}: rendering needs an extra package: {e}") from None
        if frame is None:
            raise RuntimeError(f"{self.spec.id}: this env cannot render rgb_array frames")
        return np.asarray(frame, dtype=np.uint8)

    def close(self) -> None:
        self._env.close()


def _obs_adapter(gym_id: str, space: gym.Space):
    """(convert(obs) -> np.ndarray, shape, dtype name, kind) for a gymnasium observation space."""
    if isinstance(space, gym.spaces.Discrete):
        n, start = int(space.n), int(space.start)
        eye = np.eye(n, dtype=np.float32)
        return (lambda o: eye[int(o) - start].copy()), (n,), "float32", "vector"
    if isinstance(space, gym.spaces.Box):
        if space.dtype == np.uint8 and len(space.shape) in (2, 3):
            if len(space.shape) == 2:  # grey image: add the channel axis
                shape = (*space.shape, 1)
                return (lambda o: np.asarray(o, np.uint8)[..., None]), shape, "uint8", "image"
            return (lambda o: np.asarray(o, np.uint8)), tuple(space.shape), "uint8", "image"
        d = int(np.prod(space.shape))
        return (lambda o: np.asarray(o, np.float32).reshape(d)), (d,), "float32", "vector"
    raise ValueError(f"gym:{gym_id}: unsupported observation space {space}")
