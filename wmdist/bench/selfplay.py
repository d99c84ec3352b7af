"""MuZero CartPole self-play speed: env steps/s of the collector's policy (50 simulations,
E envs searched together in one batched MCTS per step), and where the time goes: the
network (every initial/recurrent inference), the tree (search minus network) and the envs.

Network: the CartPole preset's MLPs (latent 32, hidden 64, supports 25/5), one torch thread.
Each case is also run side by side with E=1 so the batching gain is a ratio in the same run.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Iterator

import torch

from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.envs.config import EnvConfig
from wmdist.envs.vector import make_vector_env
from wmdist.search.api import SearchConfig

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _config(simulations: int) -> MuZeroConfig:
    return MuZeroConfig(search=SearchConfig(num_simulations=simulations), latent_dim=32, hidden=[64],
                        value_support=25, reward_support=5)


def measure(num_envs: int, simulations: int, steps: int, seed: int = 0) -> dict:
    """Time `steps` vector-env steps of self-play; returns the figures of one case."""
    env_cfg = EnvConfig(id="gym:CartPole-v1")
    venv = make_vector_env(env_cfg, num_envs, seed)
    policy = MuZero(venv.spec, _config(simulations), seed).make_policy()
    step = venv.reset()
    policy.act(step.obs, step.first, step.legal, step.to_play, True)  # warm-up (numba JIT, allocations)
    net = search = env = 0.0
    start = time.perf_counter()
    for _ in range(steps):
        actions, _ = policy.act(step.obs, step.first, step.legal, step.to_play, True)
        net += policy.last_net_seconds
        search += policy.last_search_seconds
        t = time.perf_counter()
        step = venv.step(actions)
        env += time.perf_counter() - t
    total = time.perf_counter() - start
    venv.close()
    return {
        "envs": num_envs, "simulations": simulations, "steps": steps * num_envs,
        "env_steps_per_s": round(steps * num_envs / total, 1),
        "searches_per_s": round(steps / total, 2),
        "simulations_per_s": round(steps * num_envs * simulations / total, 0),
        "network_share": round(net / total, 3),
        "tree_share": round((search - net) / total, 3),
        "env_share": round(env / total, 3),
        "seconds": round(total, 2),
    }


def _side_by_side(case: str, make_policy, env_cfg: EnvConfig, path: str, num_envs: int, simulations: int,
                  steps: int, seed: int = 0) -> dict:
    """A fast inference path (the searcher's attribute `path`) against the module path, steps
    interleaved (same seed: the two make the same searches, up to float rounding for the conv
    path, so they step the same envs)."""
    runs = {}
    for name in ("module", "fast"):
        venv = make_vector_env(env_cfg, num_envs, seed)
        policy = make_policy(venv.spec)
        assert getattr(policy.searcher, path) is not None, f"no {path} path for this network"
        if name == "module":
            setattr(policy.searcher, path, None)
        step = venv.reset()
        policy.act(step.obs, step.first, step.legal, step.to_play, True)  # warm-up
        runs[name] = [venv, policy, step, 0.0, 0.0, 0.0]  # venv, policy, last step, seconds, network s, CPU s
    for _ in range(steps):
        for r in runs.values():
            venv, policy, step = r[0], r[1], r[2]
            t, c = time.perf_counter(), time.process_time()
            actions, _ = policy.act(step.obs, step.first, step.legal, step.to_play, True)
            r[2] = venv.step(actions)
            r[3] += time.perf_counter() - t
            r[5] += time.process_time() - c  # CPU seconds: the ratio that a loaded machine leaves intact
            r[4] += policy.last_net_seconds
    for r in runs.values():
        r[0].close()
    rate = {k: steps * num_envs / r[3] for k, r in runs.items()}
    return {"case": case, "envs": num_envs, "simulations": simulations, "steps": steps * num_envs,
            "module_env_steps_per_s": round(rate["module"], 1), "fast_env_steps_per_s": round(rate["fast"], 1),
            "module_network_share": round(runs["module"][4] / runs["module"][3], 3),
            "fast_network_share": round(runs["fast"][4] / runs["fast"][3], 3),
            "speedup": round(rate["fast"] / rate["module"], 2),
            "speedup_cpu_seconds": round(runs["module"][5] / runs["fast"][5], 2),
            "speedup_network_seconds": round(runs["module"][4] / runs["fast"][4], 2)}


def fast_vs_module(num_envs: int, simulations: int, steps: int, seed: int = 0) -> dict:
    """The MLP fast inference path against the module path (CartPole)."""
    return _side_by_side("fast_mlp_vs_module", lambda spec: MuZero(spec, _config(simulations), seed).make_policy(),
                         EnvConfig(id="gym:CartPole-v1"), "fast", num_envs, simulations, steps, seed)


def folded_conv_vs_module(preset: str, steps: int, seed: int = 0) -> dict:
    """The folded conv path (`algos/muzero/fast_conv.py`) against the module path, with a MinAtar
    preset's network, envs and simulations (weights as initialised: the speed does not depend on them)."""
    from wmdist.algos.registry import resolve
    from wmdist.config.loader import load_config

    cfg = load_config(CONFIGS / preset)
    algo = resolve(cfg.algo_name)
    row = _side_by_side("folded_conv_vs_module", lambda spec: algo(spec, cfg.algo, seed).make_policy(), cfg.env,
                        "conv", cfg.actors.envs_per_actor, cfg.algo.search.num_simulations, steps, seed)
    return {**row, "preset": preset}


def run(quick: bool = False) -> Iterator[dict]:
    torch.set_num_threads(1)
    steps = 10 if quick else 60
    base = measure(1, 50, steps * 2)
    base["speedup_vs_E1"] = 1.0
    yield base
    for e in (8, 32):
        case = measure(e, 50, steps)
        case["speedup_vs_E1"] = round(case["env_steps_per_s"] / base["env_steps_per_s"], 2)
        yield case
    yield fast_vs_module(32, 50, steps)
    for preset in ("muzero_minatar_breakout.yaml", "efficientzero_minatar_breakout.yaml"):
        yield folded_conv_vs_module(preset, steps // 2)


if __name__ == "__main__":  # pragma: no cover
    import json

    for row in run(quick=True):
        print(json.dumps(row))
