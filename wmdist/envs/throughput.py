"""Env throughput: wmdist's Env and VectorEnv against the raw simulator, side by side.

`run(quick)` yields one dict per env id: raw simulator steps/s (the reference: the
gymnasium / dm_control / ALE env stepped directly with the same actions, no wmdist code;
for Atari the v5 env with its built-in frameskip 4 and no max-pool, resize or stack),
steps/s through the single `Env`, env-steps/s through a `VectorEnv` of 8, and the
ratios to the reference. Meant to
be exposed as the bench `envs` (`wmdist/bench/envs.py` re-exporting `run`).
"""
from __future__ import annotations

import time
from typing import Callable, Iterator

import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import make_env
from wmdist.envs.vector import make_vector_env

NUM_ENVS = 8


def _rate(step: Callable[[int], None], n: int, repeats: int = 3) -> float:
    """Calls per second: the best of `repeats` runs of n // repeats calls (the machine is shared)."""
    step(0)  # warm up (first render, lazy imports)
    chunk = max(1, n // repeats)
    best = 0.0
    for r in range(repeats):
        t0 = time.perf_counter()
        for i in range(r * chunk, (r + 1) * chunk):
            step(i)
        best = max(best, chunk / (time.perf_counter() - t0))
    return best


def _raw_stepper(cfg: EnvConfig, acts: np.ndarray) -> tuple[Callable[[int], None], Callable[[], None]]:
    """Step the underlying simulator directly (reference) with `acts[i]`, resetting on ends."""
    family, _, name = cfg.id.partition(":")
    if family in ("gym", "carracing"):  # carracing: gymnasium's own renderer, 96x96 frames
        import gymnasium as gym

        env = gym.make(name)
        env.reset(seed=0)

        def step(i: int) -> None:
            a = acts[i] if isinstance(env.action_space, gym.spaces.Discrete) else acts[i] * env.action_space.high
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()

        return step, env.close
    if family == "dmc":
        from dm_control import suite

        denv = suite.load(*name.split("-", 1), task_kwargs={"random": 0})
        denv.reset()
        def step(i: int) -> None:
            if denv.step(acts[i]).last():
                denv.reset()
            if cfg.pixels:
                denv.physics.render(height=cfg.image_size, width=cfg.image_size, camera_id=0)

        return step, denv.close
    if family == "atari":
        import ale_py
        import gymnasium as gym

        gym.register_envs(ale_py)
        aenv = gym.make(f"ALE/{name}-v5", repeat_action_probability=0.0)  # frameskip 4, no preprocessing
        aenv.reset(seed=0)

        def step(i: int) -> None:
            _, _, term, trunc, _ = aenv.step(int(acts[i]))
            if term or trunc:
                aenv.reset()

        return step, aenv.close
    from wmdist.envs.boardgames.game import GAMES

    game = GAMES[name]
    state = [game.initial()]
    rng = np.random.default_rng(0)

    def step(i: int) -> None:
        s = game.apply(state[0], int(rng.choice(np.flatnonzero(game.legal(state[0])))))
        state[0] = game.initial() if game.terminal(s) else s

    return step, lambda: None


def _case(cfg: EnvConfig, n: int) -> dict:
    env = make_env(cfg, seed=0)
    env.reset()
    spec = env.spec
    rng = np.random.default_rng(0)
    if spec.discrete:
        acts = rng.integers(0, spec.num_actions, size=(n + 1, NUM_ENVS))
    else:  # in [-1, 1]; the raw gym reference scales by its bound like the wrapper's clip
        acts = rng.uniform(-1, 1, (n + 1, NUM_ENVS, *spec.action_shape)).astype(np.float32)
    board = spec.players > 1

    def legal_pick(legal: np.ndarray) -> np.ndarray:  # [k, A] -> [k] a random legal action each
        return np.array([rng.choice(np.flatnonzero(m)) for m in legal])

    def single(i: int) -> None:
        a = legal_pick(env.legal_actions()[None])[0] if board else acts[i, 0]
        _, _, term, trunc = env.step(a)
        if term or trunc:
            env.reset()

    one = _rate(single, n)
    env.close()
    raw_step, raw_close = _raw_stepper(cfg, acts[:, 0])
    raw = _rate(raw_step, n)
    raw_close()
    vec = make_vector_env(cfg, NUM_ENVS, seed=0)
    last = [vec.reset()]

    def vstep(i: int) -> None:
        last[0] = vec.step(legal_pick(last[0].legal) if board else acts[i])

    vec_rate = _rate(vstep, max(1, n // NUM_ENVS)) * NUM_ENVS
    vec.close()
    return {
        "env": cfg.id, "pixels": cfg.pixels, "steps": n,
        "raw_steps_per_s": round(raw, 1), "env_steps_per_s": round(one, 1),
        "vector_env_steps_per_s": round(vec_rate, 1), "num_envs": NUM_ENVS,
        "env_over_raw": round(one / raw, 3), "vector_over_raw": round(vec_rate / raw, 3),
    }


def run(quick: bool = False) -> Iterator[dict]:
    """One dict per env id: raw vs wrapped vs vectorised step rates."""
    n = 200 if quick else 2000
    cases = [
        EnvConfig(id="gym:CartPole-v1"),
        EnvConfig(id="board:tictactoe"),
        EnvConfig(id="dmc:cartpole-balance"),
        EnvConfig(id="atari:Pong"),
        EnvConfig(id="dmc:cartpole-balance", pixels=True),
        EnvConfig(id="carracing:CarRacing-v3"),
    ]
    for cfg in cases:
        # software rendering is ~100x slower; CarRacing's first 50 frames zoom in, so its
        # steps reach past them to the frames an episode is made of
        steps = max(16, n // 20) if cfg.pixels else (n // 4 if cfg.id.startswith("carracing:") else n)
        yield _case(cfg, steps)
