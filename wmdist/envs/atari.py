"""`atari:<Game>`: Arcade Learning Environment games with the standard preprocessing.

Per agent step (Mnih et al. 2015; Machado et al. 2018): repeat the action for
`frame_skip` emulator frames, max-pool the last two frames (sprites flicker), resize to
`screen_size` x `screen_size` grey (or RGB), and stack the last `frame_stack` frames
along channels -> obs `(H, W, C*k)` uint8. Reset plays 1..`noop_max` no-ops. Sticky
actions are ALE's `repeat_action_probability`; the emulator frame cap (108,000 frames =
27,000 agent steps) is reported as `truncated`. With `terminal_on_life_loss` a lost life
ends the episode but the next `reset()` continues the same game (full reset only on game
over), as DQN did.

Resizing uses Pillow's area filter (gymnasium's AtariPreprocessing needs OpenCV, which
wmdist does not depend on); stacking uses gymnasium's FrameStackObservation.
"""
from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from PIL import Image

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env, check_discrete_action
from wmdist.envs.spec import EnvSpec


def atari_games() -> list[str]:
    """Game names usable as `atari:<Game>` (from the `ALE/<Game>-v5` registrations)."""
    _register()
    return sorted(
        k[len("ALE/"):-len("-v5")] for k in gym.registry if k.startswith("ALE/") and k.endswith("-v5")
    )


def _register() -> None:
    import ale_py

    gym.register_envs(ale_py)


class AtariPreprocess(gym.Wrapper):
    """Frame skip with max-pool, no-op reset, resize, optional life-loss terminal.

    Wraps an ALE env built with `frameskip=1`. Observations: `(S, S)` grey or `(S, S, 3)`.
    """

    def __init__(self, env: gym.Env, cfg: EnvConfig) -> None:
        super().__init__(env)
        self._skip = cfg.frame_skip
        self._size = cfg.screen_size
        self._noop_max = cfg.noop_max
        self._life_loss = cfg.terminal_on_life_loss
        self._lives = 0
        self._life_lost = False  # the last step ended an episode on a lost life, game not over
        self._ale = env.unwrapped.ale
        self._action_set = env.unwrapped.ale.getMinimalActionSet()  # action index -> ALE code
        self._grey = cfg.grayscale
        h, w = self._ale.getScreenDims()
        self._buf = [np.zeros((h, w) if cfg.grayscale else (h, w, 3), np.uint8) for _ in range(2)]
        shape = (self._size, self._size) if cfg.grayscale else (self._size, self._size, 3)
        self.observation_space = gym.spaces.Box(0, 255, shape, np.uint8)

    def _resize(self, frame: np.ndarray) -> np.ndarray:
        img = Image.fromarray(frame).resize((self._size, self._size), Image.Resampling.BOX)
        return np.asarray(img, dtype=np.uint8)

    def _lives_now(self) -> int:
        return int(self._ale.lives())

    def _grab(self, out: np.ndarray) -> np.ndarray:
        if self._grey:
            self._ale.getScreenGrayscale(out)
        else:
            self._ale.getScreenRGB(out)
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if not self._life_lost or seed is not None:
            _, info = self.env.reset(seed=seed, options=options)
            noops = int(self.env.unwrapped.np_random.integers(1, self._noop_max + 1)) if self._noop_max else 0
            for _ in range(noops):
                _, _, terminated, truncated, info = self.env.step(0)
                if terminated or truncated:
                    _, info = self.env.reset()
        else:
            # A life was lost but the game goes on: one no-op moves past the lost life.
            _, _, terminated, truncated, info = self.env.step(0)
            if terminated or truncated:
                _, info = self.env.reset()
        self._life_lost = False
        self._lives = self._lives_now()
        return self._resize(self._grab(self._buf[1])), info

    def step(self, action: int):
        # Drive the emulator directly: the gymnasium step would copy a screen every frame.
        ale, code = self._ale, self._action_set[action]
        total, t = 0.0, 0
        for t in range(self._skip):
            total += float(ale.act(code))  # sticky actions happen inside ALE
            if t == self._skip - 2:
                self._grab(self._buf[0])
            if ale.game_over(with_truncation=True):
                break
        frame = self._grab(self._buf[1])
        if self._skip > 1 and t == self._skip - 1:
            frame = np.maximum(self._buf[0], frame)  # max-pool the last two frames (flicker)
        terminated = bool(ale.game_over(with_truncation=False))
        truncated = bool(ale.game_truncated()) and not terminated
        if self._life_loss and not (terminated or truncated):
            lives = self._lives_now()
            self._life_lost = terminated = lives < self._lives  # the game resumes on reset()
            self._lives = lives
        return self._resize(frame), total, terminated, truncated, {}


class AtariEnv(Env):
    """An ALE game: preprocessed, frame-stacked, channels-last uint8 observations."""

    def __init__(self, cfg: EnvConfig, seed: int, game: str) -> None:
        if cfg.action_repeat != 1:
            raise ValueError("atari: use env.frame_skip, not env.action_repeat (must be 1)")
        _register()
        raw = gym.make(
            f"ALE/{game}-v5",
            frameskip=1,  # AtariPreprocess does the skipping (and max-pooling)
            repeat_action_probability=float(cfg.sticky_actions),
            max_num_frames_per_episode=int(cfg.max_episode_frames) or None,
            obs_type="grayscale" if cfg.grayscale else "rgb",
            full_action_space=False,
            render_mode="rgb_array",
            max_episode_steps=None,
        )
        self._env = gym.wrappers.FrameStackObservation(AtariPreprocess(raw, cfg), cfg.frame_stack)
        self._seed: int | None = int(seed)
        self._steps = 0
        frames_cap = math.ceil(cfg.max_episode_frames / cfg.frame_skip) if cfg.max_episode_frames else None
        self._max_steps = cfg.max_steps(frames_cap)
        channels = (1 if cfg.grayscale else 3) * cfg.frame_stack
        self.spec = EnvSpec(
            id=f"atari:{game}", obs_shape=(cfg.screen_size, cfg.screen_size, channels),
            obs_dtype="uint8", obs_kind="image",
            num_actions=int(self._env.action_space.n), max_episode_steps=self._max_steps,
        )

    def _obs(self, stacked: np.ndarray) -> np.ndarray:
        s = np.asarray(stacked)  # [k, H, W] grey or [k, H, W, 3] RGB
        if s.ndim == 3:
            return np.ascontiguousarray(s.transpose(1, 2, 0))  # [H, W, k]
        k, h, w, c = s.shape
        return np.ascontiguousarray(s.transpose(1, 2, 0, 3).reshape(h, w, k * c))  # [H, W, k*3]

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is None and self._seed is not None:
            seed = self._seed  # the construction seed starts the first episode
        self._seed = None
        self._steps = 0
        obs, _ = self._env.reset(seed=seed)
        return self._obs(obs)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = check_discrete_action(action, self.spec.num_actions)
        obs, reward, terminated, truncated, _ = self._env.step(a)
        self._steps += 1
        if self._max_steps is not None and self._steps >= self._max_steps and not terminated:
            truncated = True
        return self._obs(obs), float(reward), bool(terminated), bool(truncated)

    def render(self) -> np.ndarray:
        return np.asarray(self._env.unwrapped.ale.getScreenRGB(), dtype=np.uint8)  # [210, 160, 3]

    def close(self) -> None:
        self._env.close()
