"""Shared checks for env tests."""
from __future__ import annotations

import numpy as np

from wmdist.envs import Env


def assert_obs_matches_spec(env: Env, obs: np.ndarray) -> None:
    spec = env.spec
    assert obs.shape == tuple(spec.obs_shape), (obs.shape, spec.obs_shape)
    assert obs.dtype == np.dtype(spec.obs_dtype)


def random_action(env: Env, rng: np.random.Generator):
    spec = env.spec
    if spec.discrete:
        return int(rng.choice(np.flatnonzero(env.legal_actions())))
    return rng.uniform(spec.action_low, spec.action_high).astype(np.float32)


def rollout(env: Env, steps: int, seed: int) -> tuple[list[np.ndarray], list[float]]:
    """Observations and rewards of `steps` random steps (fixed action seed), resetting on ends."""
    rng = np.random.default_rng(123)
    obs = [env.reset(seed=seed)]
    rewards = []
    for _ in range(steps):
        o, r, term, trunc = env.step(random_action(env, rng))
        rewards.append(r)
        obs.append(env.reset() if (term or trunc) else o)
    return obs, rewards
