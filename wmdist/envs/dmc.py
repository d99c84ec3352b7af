"""`dmc:<domain>-<task>`: the DeepMind Control Suite behind the wmdist `Env` interface.

State observations are the task's observation dict flattened (in the suite's order) to
one float32 vector; with `pixels` they are `image_size x image_size` RGB uint8 frames
rendered offscreen (MuJoCo EGL on a headless machine). A suite episode ending with
discount 0 is `terminated`; the time limit is `truncated`.
"""
from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_continuous_action
from wmdist.envs.spec import EnvSpec

# Headless rendering: must be set before mujoco/dm_control are first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

# Cameras the Dreamer/PlaNet line of work renders from (quadruped's 0 is useless).
_DEFAULT_CAMERA = {"quadruped": 2}


def dmc_task_names() -> list[str]:
    """Every `<domain>-<task>` of the suite (imports dm_control)."""
    from dm_control import suite

    return [f"{d}-{t}" for d, t in suite.ALL_TASKS]


class DMCEnv(Env):
    """A dm_control suite task with action repeat, a step cap and optional pixels."""

    def __init__(self, cfg: EnvConfig, seed: int, name: str) -> None:
        from dm_control import suite

        domain, _, task = name.partition("-")
        self._repeat = cfg.action_repeat
        self._pixels = cfg.pixels
        self._size = cfg.image_size
        self._camera = cfg.camera if cfg.camera >= 0 else _DEFAULT_CAMERA.get(domain, 0)
        self._seed: int | None = int(seed)
        task_kwargs: dict[str, Any] = {"random": int(seed)}
        if cfg.time_limit:
            task_kwargs["time_limit"] = float("inf")  # our own counter truncates instead
        self._env = suite.load(domain, task, task_kwargs=task_kwargs)
        suite_steps = self._env._step_limit  # control steps per episode (1000 in most tasks)
        default = math.ceil(suite_steps / self._repeat) if math.isfinite(suite_steps) else None
        self._max_steps = cfg.max_steps(default)
        self._steps = 0
        aspec = self._env.action_spec()
        if self._pixels:
            obs_shape, obs_dtype, kind = (self._size, self._size, 3), "uint8", "image"
        else:
            dim = sum(int(np.prod(s.shape)) for s in self._env.observation_spec().values())
            obs_shape, obs_dtype, kind = (dim,), "float32", "vector"
        self.spec = EnvSpec(
            id=f"dmc:{name}", obs_shape=obs_shape, obs_dtype=obs_dtype, obs_kind=kind,
            action_shape=tuple(aspec.shape),
            action_low=tuple(float(x) for x in np.broadcast_to(aspec.minimum, aspec.shape)),
            action_high=tuple(float(x) for x in np.broadcast_to(aspec.maximum, aspec.shape)),
            max_episode_steps=self._max_steps,
        )

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is None and self._seed is not None:
            seed = self._seed  # the construction seed starts the first episode
        self._seed = None
        if seed is not None:
            self._env.task.random.seed(seed)  # reseed the task's RandomState in place
        self._steps = 0
        return self._observe(self._env.reset())

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = check_continuous_action(action, self.spec).astype(np.float64)
        total, terminated, truncated = 0.0, False, False
        for _ in range(self._repeat):
            ts = self._env.step(a)
            total += float(ts.reward or 0.0)
            if ts.last():
                # discount 0 marks a true terminal; discount 1 the suite's time limit.
                terminated = ts.discount == 0.0
                truncated = not terminated
                break
        self._steps += 1
        if not terminated and self._max_steps is not None and self._steps >= self._max_steps:
            truncated = True
        return self._observe(ts), total, terminated, truncated

    def _observe(self, ts: Any) -> np.ndarray:
        if self._pixels:
            return self.render()
        parts = [np.asarray(v, dtype=np.float32).ravel() for v in ts.observation.values()]
        return np.concatenate(parts)  # [D]

    def render(self) -> np.ndarray:
        frame = self._env.physics.render(height=self._size, width=self._size, camera_id=self._camera)
        return np.ascontiguousarray(frame, dtype=np.uint8)  # [H, W, 3]

    def close(self) -> None:
        env, self._env = getattr(self, "_env", None), None
        if env is not None:
            env.close()
