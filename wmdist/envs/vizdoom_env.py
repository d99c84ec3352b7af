"""`vizdoom:TakeCover`: ViZDoom's Take Cover scenario (the `vizdoom` package) from pixels.

World Models' Doom experiment (Ha & Schmidhuber 2018, docs/reference.md#world-models): the
agent strafes left or right to dodge fireballs; reward +1 per frame survived, and an episode
is capped at 2100 frames (the paper's cap; the scenario itself has none). Frames are rendered
at 160x120 RGB and resized to image_size x image_size (the paper: 64x64). Actions: 0 stay,
1 move left, 2 move right (the scenario's two buttons, none or one pressed).
"""
from __future__ import annotations

import os
import tempfile
from typing import Any

import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_discrete_action
from wmdist.envs.resize import resize_square
from wmdist.envs.spec import EnvSpec

# wmdist name -> (scenario config file, the paper's episode cap in agent steps)
VIZDOOM_SCENARIOS: dict[str, tuple[str, int]] = {"TakeCover": ("take_cover.cfg", 2100)}
_BUTTONS = ([0, 0], [1, 0], [0, 1])  # stay, MOVE_LEFT, MOVE_RIGHT


def vizdoom_names() -> list[str]:
    return sorted(VIZDOOM_SCENARIOS)


class VizDoomEnv(Env):
    def __init__(self, cfg: EnvConfig, seed: int, name: str) -> None:
        import vizdoom

        scenario, cap = VIZDOOM_SCENARIOS[name]
        game = vizdoom.DoomGame()
        game.load_config(os.path.join(vizdoom.scenarios_path, scenario))
        game.set_window_visible(False)
        game.set_sound_enabled(False)
        game.set_screen_resolution(vizdoom.ScreenResolution.RES_160X120)
        game.set_screen_format(vizdoom.ScreenFormat.RGB24)
        game.set_seed(int(seed))
        # the engine writes its settings file; by default into the working directory
        game.set_doom_config_path(os.path.join(tempfile.gettempdir(), f"wmdist-vizdoom-{os.getuid()}.ini"))
        game.init()
        self._game, self._side, self._repeat = game, cfg.image_size, cfg.action_repeat
        self._max_steps = cfg.max_steps(-(-cap // self._repeat))
        self._steps = 0
        self._frame = np.zeros((120, 160, 3), np.uint8)
        self._pending_seed: int | None = None
        self.spec = EnvSpec(id=f"vizdoom:{name}", obs_shape=(self._side, self._side, 3), obs_dtype="uint8",
                            obs_kind="image", num_actions=len(_BUTTONS), max_episode_steps=self._max_steps)

    def _obs(self) -> np.ndarray:
        state = self._game.get_state()
        if state is not None:  # None once the episode is over: the last frame stays
            self._frame = np.asarray(state.screen_buffer, np.uint8)
        return resize_square(self._frame, self._side)

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is not None:
            self._game.set_seed(int(seed))
        self._game.new_episode()
        self._steps = 0
        return self._obs()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = check_discrete_action(action, len(_BUTTONS))
        reward = float(self._game.make_action(list(_BUTTONS[a]), self._repeat))
        self._steps += 1
        terminated = bool(self._game.is_episode_finished())
        truncated = not terminated and self._max_steps is not None and self._steps >= self._max_steps
        return self._obs(), reward, terminated, truncated

    def render(self) -> np.ndarray:
        return self._frame.copy()

    def close(self) -> None:
        if self._game is not None:
            self._game.close()
            self._game = None
