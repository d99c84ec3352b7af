"""`nav:<layout>`: a point mass that has to reach a goal, seen from pixels (goal-reaching tasks).

Layouts:
    tworooms   the unit square split by a vertical wall at x = 0.5 with a door in its middle
               (a two-room navigation task as in LeWorldModel's Two-Room, docs/reference.md)
    open       the same square without the wall

Each episode draws a start and a goal uniformly over the free space (at least
`_MIN_GOAL_DIST` apart). The observation is one uint8 image [S, S, 6]: channels 0..2 are
the current frame, 3..5 the goal image, which is the frame of the solved state (the agent
drawn at the goal), so a goal-conditioned policy finds the goal in the data replay stores.

An action in [-1, 1]^2 moves the agent by `_STEP` times the action in four sub-steps; a
sub-step that would enter the wall slides along it (the blocked axis is dropped). The
reward is 1 on arriving within `_RADIUS` of the goal, which ends the episode (terminated),
else 0, so an episode's return is its success (1 = reached within the step budget, the
time limit: `env.time_limit`, default `_BUDGET` steps). Deterministic given the seed.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_continuous_action
from wmdist.envs.spec import EnvSpec

NAV_LAYOUTS = ("open", "tworooms")
_STEP = 0.08  # largest move per step along each axis (the square's side is 1)
_SUBSTEPS = 4
_RADIUS = 0.08  # success: within this distance of the goal
_MIN_GOAL_DIST = 0.25  # start and goal drawn at least this far apart
_BUDGET = 50  # default step budget (time limit)
_WALL_HALF = 0.03  # the wall spans x in [0.5 - w, 0.5 + w]
_DOOR = (0.35, 0.65)  # y range of the door
_MARGIN = 0.04  # the agent's centre stays this far from the outer border
_AGENT_PX = 0.06  # drawn radius of the agent (square's side = 1)
_FLOOR, _WALL, _AGENT = (235, 235, 225), (70, 70, 80), (220, 40, 40)


def nav_layouts() -> list[str]:
    """Names usable as `nav:<layout>`."""
    return list(NAV_LAYOUTS)


def blocked(xy: np.ndarray, walls: bool) -> bool:
    """Whether the point `xy` [2] lies outside the free space."""
    x, y = float(xy[0]), float(xy[1])
    if not (_MARGIN <= x <= 1 - _MARGIN and _MARGIN <= y <= 1 - _MARGIN):
        return True
    return walls and abs(x - 0.5) < _WALL_HALF + _MARGIN and not (_DOOR[0] + _MARGIN < y < _DOOR[1] - _MARGIN)


def move(xy: np.ndarray, action: np.ndarray, walls: bool) -> np.ndarray:
    """The position after one step of `action` [2] in [-1, 1] from `xy` [2]."""
    pos = xy.astype(np.float64).copy()
    delta = _STEP * np.asarray(action, np.float64) / _SUBSTEPS
    for _ in range(_SUBSTEPS):
        for step in (delta, np.array([delta[0], 0.0]), np.array([0.0, delta[1]])):  # slide along a wall
            if not blocked(pos + step, walls):
                pos = pos + step
                break
    return pos


class NavEnv(Env):
    """One point-mass navigation episode after another; `seed` fixes every start and goal."""

    def __init__(self, cfg: EnvConfig, seed: int, layout: str) -> None:
        if cfg.action_repeat != 1:
            raise ValueError(f"nav: env.action_repeat must be 1, got {cfg.action_repeat}")
        self._walls = layout == "tworooms"
        self._side = cfg.image_size
        self._rng = np.random.default_rng(seed)
        self._max_steps = cfg.max_steps(_BUDGET)
        self._steps = 0
        self.spec = EnvSpec(
            id=f"nav:{layout}", obs_shape=(self._side, self._side, 6), obs_dtype="uint8", obs_kind="image",
            action_shape=(2,), action_low=(-1.0, -1.0), action_high=(1.0, 1.0), max_episode_steps=self._max_steps,
        )
        grid = (np.arange(self._side) + 0.5) / self._side  # pixel centres in [0, 1]
        self._gx, self._gy = np.meshgrid(grid, grid[::-1])  # [S, S]; row 0 is the top (y = 1)
        self._background = self._draw_background()
        self.pos = np.zeros(2)
        self.goal = np.zeros(2)
        self._goal_frame = self._background

    def _draw_background(self) -> np.ndarray:
        img = np.empty((self._side, self._side, 3), np.uint8)
        img[:] = _FLOOR
        if self._walls:
            wall = (np.abs(self._gx - 0.5) < _WALL_HALF) & ~((self._gy > _DOOR[0]) & (self._gy < _DOOR[1]))
            img[wall] = _WALL
        return img

    def frame(self, xy: np.ndarray) -> np.ndarray:
        """The [S, S, 3] uint8 picture of the agent at `xy`."""
        img = self._background.copy()
        img[(self._gx - xy[0]) ** 2 + (self._gy - xy[1]) ** 2 <= _AGENT_PX**2] = _AGENT
        return img

    def _free_point(self) -> np.ndarray:
        while True:
            xy = self._rng.uniform(0, 1, 2)
            if not blocked(xy, self._walls):
                return xy

    def _obs(self) -> np.ndarray:
        return np.concatenate([self.frame(self.pos), self._goal_frame], -1)  # [S, S, 6]

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self.pos = self._free_point()
        self.goal = self._free_point()
        while np.linalg.norm(self.goal - self.pos) < _MIN_GOAL_DIST:
            self.goal = self._free_point()
        self._goal_frame = self.frame(self.goal)
        self._steps = 0
        return self._obs()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = check_continuous_action(action, self.spec)
        self.pos = move(self.pos, a, self._walls)
        self._steps += 1
        reached = bool(np.linalg.norm(self.pos - self.goal) <= _RADIUS)
        truncated = not reached and self._max_steps is not None and self._steps >= self._max_steps
        return self._obs(), float(reached), reached, truncated

    def render(self) -> np.ndarray:
        """The current frame beside the goal image: [S, 2S, 3]."""
        return np.concatenate([self.frame(self.pos), self._goal_frame], 1)
