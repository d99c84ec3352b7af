"""nav:<layout> (wmdist/envs/nav.py): shapes, determinism, the wall, success as the return."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import check_id, make_env
from wmdist.envs.nav import blocked, move


def _env(layout: str = "tworooms", seed: int = 0, **kw):
    return make_env(EnvConfig(id=f"nav:{layout}", **kw), seed)


def test_observation_is_the_frame_and_the_goal_image():
    env = _env()
    obs = env.reset()
    assert obs.shape == (64, 64, 6) and obs.dtype == np.uint8
    assert env.spec.obs_shape == (64, 64, 6) and env.spec.action_shape == (2,)
    np.testing.assert_array_equal(obs[..., :3], env.frame(env.pos))
    np.testing.assert_array_equal(obs[..., 3:], env.frame(env.goal))  # the goal image is the solved state's frame
    assert not np.array_equal(obs[..., :3], obs[..., 3:])
    assert env.render().shape == (64, 128, 3)


def test_seeded_episodes_repeat_and_goals_change_per_episode():
    a, b = _env(seed=3), _env(seed=3)
    goals = []
    for _ in range(3):
        np.testing.assert_array_equal(a.reset(), b.reset())
        goals.append(a.goal.copy())
        for action in np.random.default_rng(0).uniform(-1, 1, (10, 2)):
            np.testing.assert_array_equal(a.step(action)[0], b.step(action)[0])
    assert len({tuple(g) for g in goals}) == 3


def test_the_wall_blocks_except_at_the_door():
    left = np.array([0.4, 0.15])
    for _ in range(10):
        left = move(left, np.array([1.0, 0.0]), walls=True)
    assert left[0] < 0.5  # pressed against the wall, never through it
    assert blocked(np.array([0.5, 0.15]), True) and not blocked(np.array([0.5, 0.15]), False)
    door = np.array([0.4, 0.5])
    for _ in range(5):
        door = move(door, np.array([1.0, 0.0]), walls=True)
    assert door[0] > 0.6  # through the door
    slide = move(np.array([0.42, 0.2]), np.array([1.0, 1.0]), walls=True)
    assert slide[1] > 0.2 + 0.07  # blocked in x, still moves in y


def test_reaching_the_goal_ends_the_episode_with_return_one():
    env = _env("open", seed=1)
    env.reset()
    total, done = 0.0, False
    for _ in range(50):
        direction = env.goal - env.pos
        _, reward, terminated, truncated = env.step(np.clip(direction / 0.08, -1, 1))
        total += reward
        if terminated or truncated:
            done = terminated
            break
    assert done and total == 1.0


def test_the_step_budget_truncates_with_return_zero():
    env = _env(seed=2, time_limit=5)
    env.reset()
    results = [env.step(np.zeros(2)) for _ in range(5)]
    assert [r[3] for r in results] == [False] * 4 + [True]
    assert sum(r[1] for r in results) == 0.0


def test_unknown_layout_is_one_line():
    with pytest.raises(ValueError, match="nav:tworooms"):
        check_id("nav:threerooms")
