"""`carracing:CarRacing-v3`: gymnasium's Box2D car racing from image_size x image_size pixels.

World Models (Ha & Schmidhuber 2018, docs/reference.md#world-models) resize each 96x96 frame
to 64x64 and act with 3 continuous actions (steer in [-1, 1], gas and brake in [0, 1]); the
reward is -0.1 per frame plus 1000/N per track tile visited, an episode is at most 1000
frames (the registered cap). The `gym:` family's env with its frames resized and its road
drawn by a vectorised renderer (`carracing_render.py`: the same pixels); needs
gymnasium's box2d extra (`box2d`). `render()` gives gymnasium's 600x400 view.
"""
from __future__ import annotations

import dataclasses

from wmdist.envs.config import EnvConfig
from wmdist.envs.gym_env import GymEnv
from wmdist.envs.carracing_render import install
from wmdist.envs.resize import resize_square

CARRACING_IDS = ("CarRacing-v3",)


def carracing_names() -> list[str]:
    return list(CARRACING_IDS)


class CarRacingEnv(GymEnv):
    def __init__(self, cfg: EnvConfig, seed: int, name: str) -> None:
        super().__init__(cfg, seed, name)
        install(self._env.unwrapped)  # the same frames, ~3x faster (carracing_render.py)
        side, raw = cfg.image_size, self._obs_fn
        self._obs_fn = lambda o: resize_square(raw(o), side)  # [side, side, 3] uint8
        self.spec = dataclasses.replace(self.spec, id=f"carracing:{name}", obs_shape=(side, side, 3))
