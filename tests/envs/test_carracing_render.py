"""The vectorised CarRacing road renderer draws exactly gymnasium's frames (its own renderer is the reference)."""
import gymnasium as gym
import numpy as np
import pytest

from wmdist.envs import EnvConfig, make_env
from wmdist.envs.carracing_render import _rotation, install
from wmdist.envs.resize import resize_square


def _frames(fast: bool, seed: int, steps: int, randomize: bool) -> np.ndarray:
    """[T, 96, 96, 3]: one episode start with seeded random driving (tiles visited change colour)."""
    env = gym.make("CarRacing-v3", domain_randomize=randomize)
    if fast:
        install(env.unwrapped)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    frames = [obs]
    for _ in range(steps):
        act = rng.uniform([-1, 0.3, 0], [1, 1, 0.1]).astype(np.float32)
        obs, _, term, trunc, _ = env.step(act)
        frames.append(obs)
        if term or trunc:
            break
    if randomize:  # a second track on the same env: the cache must follow the new road
        obs, _ = env.reset(seed=seed + 100)
        frames.append(obs)
        for _ in range(10):
            frames.append(env.step(np.array([0.5, 1.0, 0.0], np.float32))[0])
    env.close()
    return np.stack(frames)


@pytest.mark.parametrize("seed,randomize", [(0, False), (7, True)])
def test_frames_equal_gymnasiums_renderer(seed, randomize):
    ref = _frames(False, seed, 120, randomize)
    ours = _frames(True, seed, 120, randomize)
    assert ref.shape == ours.shape and ref.shape[0] > 100
    assert ref.std() > 5  # real pictures, not blank ones
    assert np.array_equal(ref, ours)


def test_rotation_matches_pygame_at_quarter_turns_and_between():
    import pygame

    pts = np.array([[3.25, -1.5], [0.0, 2.0]])
    for angle in (0.0, np.pi / 2, -np.pi, 3 * np.pi / 2, 2 * np.pi, 0.3, -2.1, 17.0):
        c, s = _rotation(float(angle))
        for x, y in pts:
            v = pygame.math.Vector2(x, y).rotate_rad(float(angle))
            assert (c * x - s * y, s * x + c * y) == (v.x, v.y)


def test_wmdist_env_uses_it_and_resizes_the_same_frame():
    with make_env(EnvConfig(id="carracing:CarRacing-v3", time_limit=30), seed=3) as env:
        raw = env._env.unwrapped
        assert raw._render_road.__func__.__module__ == "wmdist.envs.carracing_render"
        obs = [env.reset()] + [env.step(np.array([0.2, 1.0, 0.0], np.float32))[0] for _ in range(30)]
    ref_env = gym.make("CarRacing-v3")
    ref = [ref_env.reset(seed=3)[0]] + [ref_env.step(np.array([0.2, 1.0, 0.0], np.float32))[0] for _ in range(30)]
    ref_env.close()
    assert np.array_equal(np.stack(obs), np.stack([resize_square(f, 64) for f in ref]))
