"""Build any wmdist environment from one string id: `family:name`.

    gym:<gymnasium id>       gym:CartPole-v1, gym:Pendulum-v1
    dmc:<domain>-<task>      dmc:cartpole-balance, dmc:walker-walk (state, or pixels)
    atari:<Game>             atari:Pong, atari:Breakout (ALE, standard preprocessing)
    minatar:<Game>           minatar:Breakout, minatar:Asterix (MinAtar 10x10 grids)
    board:<game>             board:tictactoe, board:connect4 (two players)
    carracing:CarRacing-v3   gymnasium's car racing from 64x64 pixels (World Models)
    vizdoom:<Scenario>       vizdoom:TakeCover from 64x64 pixels (World Models)
    nav:<layout>             nav:tworooms, nav:open: point-mass goal reaching from pixels (frame + goal image)
"""
from __future__ import annotations

import dataclasses
import difflib
import importlib
from functools import lru_cache

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec

_FAMILIES: dict[str, str] = {
    "gym": "any gymnasium id, e.g. gym:CartPole-v1, gym:Pendulum-v1",
    "dmc": "DeepMind Control Suite <domain>-<task>, state or pixels, e.g. dmc:cartpole-balance, dmc:walker-walk",
    "atari": "ALE game with standard preprocessing, e.g. atari:Pong, atari:Breakout",
    "minatar": "MinAtar 10x10 game: minatar:Asterix, minatar:Breakout, minatar:Freeway, minatar:Seaquest, "
               "minatar:SpaceInvaders",
    "board": "two-player board games: board:tictactoe, board:connect4",
    "carracing": "gymnasium's Box2D car racing from image_size pixels: carracing:CarRacing-v3",
    "vizdoom": "ViZDoom scenario from image_size pixels: vizdoom:TakeCover",
    "nav": "point-mass goal reaching from pixels, observation = frame + goal image (6 channels): nav:tworooms, nav:open",
}


def list_families() -> list[tuple[str, str]]:
    """(family prefix, description with examples) for every env family."""
    return list(_FAMILIES.items())


def _names(family: str) -> list[str]:
    """Every valid name of one family (imports that family's simulator)."""
    if family == "gym":
        import gymnasium as gym

        return list(gym.registry)
    if family == "dmc":
        from wmdist.envs.dmc import dmc_task_names

        return dmc_task_names()
    if family == "atari":
        from wmdist.envs.atari import atari_games

        return atari_games()
    if family == "minatar":
        from wmdist.envs.minatar import minatar_games

        return minatar_games()
    if family == "carracing":
        from wmdist.envs.carracing import carracing_names

        return carracing_names()
    if family == "vizdoom":
        from wmdist.envs.vizdoom_env import vizdoom_names

        return vizdoom_names()
    if family == "nav":
        from wmdist.envs.nav import nav_layouts

        return nav_layouts()
    from wmdist.envs.boardgames.game import GAMES

    return list(GAMES)


def _unknown(env_id: str, candidates: list[str]) -> ValueError:
    lowered = {c.lower(): c for c in candidates}
    close = difflib.get_close_matches(env_id.lower(), list(lowered), n=1, cutoff=0.4)
    hint = f"closest match: '{lowered[close[0]]}'" if close else "no close match"
    return ValueError(
        f"unknown env id '{env_id}' ({hint}); families: gym:<gymnasium id>, "
        "dmc:<domain>-<task>, atari:<Game>, minatar:<Game>, board:tictactoe|connect4, "
        "carracing:CarRacing-v3, vizdoom:TakeCover, nav:tworooms|open"
    )


def _check_dmc_task(name: str, names: list[str]) -> None:
    """A bare domain (`dmc:cartpole`) gets its own message: the closest match alone
    (`dmc:cartpole-swingup`) would not say that the task is what is missing."""
    domain = name[:-1] if name.endswith("-") else name
    tasks = [f"dmc:{n}" for n in names if n.partition("-")[0] == domain]
    if "-" not in domain and tasks:
        raise ValueError(f"dmc:{domain} names a domain but no task: dmc ids are dmc:<domain>-<task>, "
                         f"e.g. {', '.join(tasks)}")


def check_id(env_id: str) -> str:
    """Return `env_id` if it names a known env, else raise a one-line ValueError that lists
    the families and the closest known id."""
    if not isinstance(env_id, str):
        raise ValueError(f"env id must be a string like 'gym:CartPole-v1', got {env_id!r}")
    family, sep, name = env_id.partition(":")
    if sep and family in _FAMILIES:
        if family == "gym" and ":" in name:
            # gymnasium's "module:EnvId" form: importing the module registers the env
            module, _, gym_id = name.partition(":")
            try:
                importlib.import_module(module)
            except ImportError as err:
                raise ValueError(f"env id '{env_id}': cannot import module '{module}' ({err})") from None
            if gym_id in _names("gym"):
                return env_id
            raise _unknown(f"gym:{gym_id}", [f"gym:{n}" for n in _names("gym")])
        if family == "gym" and name.startswith("ALE/"):
            from wmdist.envs.atari import _register

            _register()
        names = _names(family)
        if name in names:
            return env_id
        if family == "dmc":
            _check_dmc_task(name, names)
        raise _unknown(env_id, [f"{family}:{n}" for n in names])
    # No or unknown prefix: compare against every family (a bare gymnasium id is common).
    candidates = [f"{f}:{n}" for f in _FAMILIES for n in _names(f)]
    raise _unknown(env_id, candidates)


# family -> (module, class) of its Env, constructed as cls(cfg, seed, name); imported on use
# (each family pulls in its simulator). Board games take no EnvConfig and are built below.
_CONSTRUCTORS: dict[str, tuple[str, str]] = {
    "gym": ("wmdist.envs.gym_env", "GymEnv"),
    "dmc": ("wmdist.envs.dmc", "DMCEnv"),
    "atari": ("wmdist.envs.atari", "AtariEnv"),
    "minatar": ("wmdist.envs.minatar", "MinAtarEnv"),
    "carracing": ("wmdist.envs.carracing", "CarRacingEnv"),
    "vizdoom": ("wmdist.envs.vizdoom_env", "VizDoomEnv"),
    "nav": ("wmdist.envs.nav", "NavEnv"),
}


def make_env(cfg: EnvConfig, seed: int) -> Env:
    """Build the env `cfg.id`; its first `reset()` uses `seed` (an int >= 0)."""
    cfg.validate()
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"env seed must be an int >= 0, got {seed!r}")
    family, _, name = check_id(cfg.id).partition(":")
    if cfg.pixels and family != "dmc":
        raise ValueError(f"env.pixels applies to dmc ids only, not '{cfg.id}'")
    if family in _CONSTRUCTORS:
        import importlib

        module, cls = _CONSTRUCTORS[family]
        return getattr(importlib.import_module(module), cls)(cfg, seed, name)
    if cfg.action_repeat != 1:
        raise ValueError(f"env.action_repeat must be 1 for board games, got {cfg.action_repeat}")
    from wmdist.envs.boardgames.env import BoardEnv

    return BoardEnv(name, seed, obs=cfg.board_obs)


def env_spec(cfg: EnvConfig) -> EnvSpec:
    """The EnvSpec of `cfg` (builds one env and closes it; cached per config)."""
    cfg.validate()
    return _spec_cached(dataclasses.astuple(cfg))


@lru_cache(maxsize=64)
def _spec_cached(values: tuple) -> EnvSpec:
    env = make_env(EnvConfig(*values), seed=0)
    try:
        return env.spec
    finally:
        env.close()
