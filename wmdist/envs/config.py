"""EnvConfig: the `env` section of a run config (one flat dataclass for every family)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from wmdist.config.fields import param


@dataclass
class EnvConfig:
    """Which environment to build and how to preprocess it.

    Fields that do not apply to the chosen family are ignored (e.g. Atari options for dmc).
    """

    id: str = param("gym:CartPole-v1", "env id: gym:<id>, dmc:<domain>-<task>, atari:<Game>, minatar:<Game>, board:<game>, carracing:CarRacing-v3, vizdoom:TakeCover, nav:tworooms|open")
    pixels: bool = param(False, "dmc: observe image_size x image_size RGB pixels instead of state")
    image_size: int = param(64, "dmc, carracing, vizdoom, nav: side of the square pixel observation", ge=8, le=1024)
    camera: int = param(-1, "dmc: camera id for pixels and render; -1 = domain default", ge=-1)
    action_repeat: int = param(1, "gym/dmc: repeat each action this many times, summing rewards", ge=1)
    time_limit: int | None = param(0, "episode cap in agent steps (after repeat); 0/None = family default", ge=0)
    frame_skip: int = param(4, "atari: frames per agent step, max-pooled over the last two", ge=1)
    grayscale: bool = param(True, "atari: grey frames (1 channel each) instead of RGB (3)")
    screen_size: int = param(84, "atari: side of the square resized frame", ge=8, le=1024)
    frame_stack: int = param(4, "atari: stack the last k frames along channels", ge=1)
    terminal_on_life_loss: bool = param(False, "atari: end the episode on a lost life (game resumes on reset)")
    sticky_actions: float = param(0.0, "atari: repeat_action_probability (0.25 in Machado et al.)", ge=0.0, le=1.0)
    max_episode_frames: int = param(108000, "atari: emulator frame cap (108000 = 27,000 steps); 0 = none", ge=0)
    noop_max: int = param(30, "atari: up to this many no-op actions after reset", ge=0)
    minatar_sticky_actions: float = param(0.1, "minatar: probability that the previous action repeats (MinAtar paper: 0.1)",
                                          ge=0.0, le=1.0)
    minatar_full_action_set: bool = param(True, "minatar: all 6 actions (MinAtar paper); false = the game's minimal set")
    minatar_ramping: bool = param(True, "minatar: difficulty ramping as the game goes on (MinAtar paper default)")
    minatar_obs: str = param("image", "minatar: image = uint8 (10, 10, C) of 0/255 (conv nets); "
                                      "vector = float32 (100*C,) of 0/1 (MLP encoders)", choices=("image", "vector"))
    board_obs: str = param("vector", "board: vector = float32 (3*cells,) of 0/1 (MLP nets); planes = uint8 "
                                     "(rows, cols, 3) of 0/255 (conv nets, e.g. algo.conv_stem: grid)",
                           choices=("vector", "planes"))

    def validate(self) -> "EnvConfig":
        """Raise ValueError (one line naming the field) on a wrong type or out-of-range value."""
        for f in dataclasses.fields(self):
            value: Any = getattr(self, f.name)
            if f.name == "time_limit" and value is None:
                continue
            _check_type(f.name, value, f.default)
            meta = f.metadata
            if meta.get("choices") and value not in meta["choices"]:
                raise ValueError(f"env.{f.name} must be one of {list(meta['choices'])}, got {value!r}")
            for key, ok, word in (
                ("ge", lambda v, b: v >= b, ">="),
                ("gt", lambda v, b: v > b, ">"),
                ("le", lambda v, b: v <= b, "<="),
                ("lt", lambda v, b: v < b, "<"),
            ):
                bound = meta.get(key)
                if bound is not None and not ok(value, bound):
                    raise ValueError(f"env.{f.name} must be {word} {bound}, got {value!r}")
        return self

    def max_steps(self, family_default: int | None) -> int | None:
        """The episode cap in agent steps: `time_limit` if set, else the family's default."""
        return self.time_limit if self.time_limit else family_default


def _check_type(name: str, value: Any, default: Any) -> None:
    # bool is an int subclass: check it first so `frame_skip: true` is refused.
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"env.{name} must be a bool, got {value!r}")
    elif isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"env.{name} must be an int, got {value!r}")
    elif isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"env.{name} must be a number, got {value!r}")
    elif isinstance(default, str) and not isinstance(value, str):
        raise ValueError(f"env.{name} must be a string, got {value!r}")
