"""A gymnasium env whose step takes a fixed wall time (for the collector-scaling test).

Registered on import, so `gym:tests.runtime.slow_env:SlowCartPole-v0` works in any worker."""
from __future__ import annotations

import time

import gymnasium as gym
from gymnasium.envs.classic_control import CartPoleEnv

STEP_SECONDS = 0.004


class SlowCartPole(CartPoleEnv):
    def step(self, action):
        time.sleep(STEP_SECONDS)
        return super().step(action)


if "SlowCartPole-v0" not in gym.registry:
    gym.register("SlowCartPole-v0", entry_point=SlowCartPole, max_episode_steps=200)
