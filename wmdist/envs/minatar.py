"""`minatar:<Game>`: the MinAtar games (Young & Tian 2019) through the `minatar` package.

Breakout, Asterix, Freeway, Seaquest and SpaceInvaders on a 10x10 grid with one binary
channel per kind of object. Defaults follow the MinAtar paper (docs/reference.md#minatar):
sticky actions 0.1 (the previous action repeats with that probability, inside the package),
all 6 actions, difficulty ramping on. The package's `minatar.Environment` is driven
directly; its gymnasium ids (`MinAtar/<Game>-v0`) are registered only by an explicit
`minatar.gym.register_envs()`, which wmdist never needs.

Observations (`env.minatar_obs`):
    image   uint8 (10, 10, C) channels-last, 0 or 255 (the project's image convention, so
            conv nets that scale by 1/255 see 0/1);
    vector  float32 (100 * C,) of 0/1, the grid flattened row-major (for MLP encoders).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_discrete_action
from wmdist.envs.spec import EnvSpec

# wmdist game name -> the package's module name (minatar.environments.<module>)
MINATAR_GAMES: dict[str, str] = {
    "Asterix": "asterix",
    "Breakout": "breakout",
    "Freeway": "freeway",
    "Seaquest": "seaquest",
    "SpaceInvaders": "space_invaders",
}
_FULL_ACTIONS = 6  # every MinAtar game reads the same 6 actions: n, l, u, r, d, f


def minatar_games() -> list[str]:
    """Game names usable as `minatar:<Game>`."""
    return sorted(MINATAR_GAMES)


def _palette(channels: int) -> np.ndarray:
    """[C + 1, 3] uint8: black background, then one distinct hue per channel."""
    hues = np.linspace(0.0, 1.0, channels, endpoint=False)
    rgb = 0.5 + 0.45 * np.cos(2 * np.pi * (hues[:, None] + np.array([0.0, 1 / 3, 2 / 3])))  # [C, 3]
    return (255 * np.concatenate([np.zeros((1, 3)), rgb])).astype(np.uint8)


class MinAtarEnv(Env):
    """One MinAtar game; `seed` seeds both the game and the sticky-action draws."""

    _CELL = 16  # render: pixels per grid cell

    def __init__(self, cfg: EnvConfig, seed: int, game: str) -> None:
        if cfg.action_repeat != 1:
            raise ValueError(f"minatar: env.action_repeat must be 1 (MinAtar has no frame skip), got {cfg.action_repeat}")
        if cfg.minatar_obs not in ("image", "vector"):
            raise ValueError(f"env.minatar_obs must be 'image' or 'vector', got {cfg.minatar_obs!r}")
        from minatar import Environment

        self._env = Environment(
            MINATAR_GAMES[game], sticky_action_prob=float(cfg.minatar_sticky_actions),
            difficulty_ramping=bool(cfg.minatar_ramping),
        )
        # action index -> the package's action code (0..5)
        self._actions = list(range(_FULL_ACTIONS)) if cfg.minatar_full_action_set else list(self._env.minimal_action_set())
        self._channels = int(self._env.state_shape()[2])
        self._vector = cfg.minatar_obs == "vector"
        self._seed: int | None = int(seed)
        self._steps = 0
        self._max_steps = cfg.max_steps(None)
        obs_shape = (100 * self._channels,) if self._vector else (10, 10, self._channels)
        self.spec = EnvSpec(
            id=f"minatar:{game}", obs_shape=obs_shape,
            obs_dtype="float32" if self._vector else "uint8",
            obs_kind="vector" if self._vector else "image",
            num_actions=len(self._actions), max_episode_steps=self._max_steps,
        )

    def _obs(self) -> np.ndarray:
        grid = np.asarray(self._env.state(), dtype=bool)  # [10, 10, C]
        if self._vector:
            return grid.reshape(-1).astype(np.float32)  # [100 * C]
        return grid.astype(np.uint8) * np.uint8(255)  # [10, 10, C]

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is None and self._seed is not None:
            seed = self._seed  # the construction seed starts the first episode
        self._seed = None
        if seed is not None:
            self._env.seed(int(seed))
        self._env.reset()
        self._steps = 0
        return self._obs()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = check_discrete_action(action, self.spec.num_actions)
        reward, terminated = self._env.act(self._actions[a])
        self._steps += 1
        truncated = self._max_steps is not None and self._steps >= self._max_steps and not terminated
        return self._obs(), float(reward), bool(terminated), bool(truncated)

    def render(self) -> np.ndarray:
        grid = np.asarray(self._env.state(), dtype=bool)  # [10, 10, C]
        # Colour each cell by its highest set channel (0 = empty), as the package's display does.
        idx = np.max(grid * np.arange(1, self._channels + 1), axis=2)  # [10, 10]
        img = _palette(self._channels)[idx]  # [10, 10, 3]
        return np.ascontiguousarray(img.repeat(self._CELL, 0).repeat(self._CELL, 1))  # [160, 160, 3]
