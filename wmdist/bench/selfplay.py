"""MuZero CartPole self-play speed: env steps/s of the collector's policy (50 simulations,
E envs searched together in one batched MCTS per step), and where the time goes: the
network (every initial/recurrent inference), the tree (search minus network) and the envs.

Network: the CartPole preset's MLPs (latent 32, hidden 64, supports 25/5), one torch thread.
Each case is also run side by side with E=1 so the batching gain is a ratio in the same run.
"""
from __future__ import annotations

import time
from typing import Iterator

import torch

from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.envs.config import EnvConfig
from wmdist.envs.vector import make_vector_env
from wmdist.search.api import SearchConfig


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


def fast_vs_module(num_envs: int, simulations: int, steps: int, seed: int = 0) -> dict:
    """The MLP fast inference path against the module path, steps interleaved (same seed: the
    two make identical searches, so they step identical envs)."""
    env_cfg = EnvConfig(id="gym:CartPole-v1")
    runs = {}
    for name in ("module", "fast"):
        venv = make_vector_env(env_cfg, num_envs, seed)
        policy = MuZero(venv.spec, _config(simulations), seed).make_policy()
        if name == "module":
            policy.searcher.fast = None
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
    return {"case": "fast_mlp_vs_module", "envs": num_envs, "simulations": simulations, "steps": steps * num_envs,
            "module_env_steps_per_s": round(rate["module"], 1), "fast_env_steps_per_s": round(rate["fast"], 1),
            "module_network_share": round(runs["module"][4] / runs["module"][3], 3),
            "fast_network_share": round(runs["fast"][4] / runs["fast"][3], 3),
            "speedup": round(rate["fast"] / rate["module"], 2),
            "speedup_cpu_seconds": round(runs["module"][5] / runs["fast"][5], 2)}


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


if __name__ == "__main__":  # pragma: no cover
    import json

    for row in run(quick=True):
        print(json.dumps(row))
