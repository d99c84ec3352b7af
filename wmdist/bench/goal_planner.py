"""Planning time per decision on nav:tworooms: JEPA's goal planner beside PlaNet's planner.

Both plan with the same CEM settings (the JEPA preset's, configs/jepa_nav_tworooms.yaml) from
the same [E, 64, 64, 6] observations, through each policy's whole greedy `act` (encode, then
CEM): JEPA rolls its MLP predictor and scores the distance to the goal image's embedding (with
the preset's waypoint graph: the nearest node, and a shortest-path search once per goal);
PlaNet filters the frame through its RSSM (the pixel preset's sizes: GRU 200, Gaussian 30,
conv depth 32) and scores predicted rewards. Weights are random (the cost does not depend on
them), one torch thread. `ms_per_decision` = wall time / (E x calls); `*_cpu` = this thread's
CPU time instead (what it costs on a shared machine).
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Iterator

import numpy as np
import torch

from wmdist.algos.base import Policy

PRESET = Path(__file__).parents[2] / "configs" / "jepa_nav_tworooms.yaml"


def _policies() -> dict[str, Policy]:
    from wmdist.algos.jepa import Jepa
    from wmdist.algos.jepa.model import GRAPH_KEY, UPDATES_KEY
    from wmdist.algos.planet import PlaNet, PlaNetConfig
    from wmdist.config.loader import load_config
    from wmdist.envs.factory import env_spec

    cfg = load_config(str(PRESET))
    spec = env_spec(cfg.env)
    jepa = Jepa(spec, cfg.algo)
    planet = PlaNet(spec, PlaNetConfig(planner=cfg.algo.planner))
    out = {}
    for name, algo in (("jepa", jepa), ("planet", planet)):
        policy = algo.make_policy()
        weights = algo.make_learner().get_weights()
        if name == "jepa":
            weights[UPDATES_KEY] = np.asarray(1, np.int64)  # planning needs weights from an update
            if cfg.algo.graph_pairs:  # the preset's waypoint graph, of its size (random nodes: the cost is the same)
                rng = np.random.default_rng(0)
                nodes = rng.normal(size=(2 * cfg.algo.graph_pairs, cfg.algo.embed_dim))  # [2P, D]
                weights[GRAPH_KEY] = nodes.astype(np.float32)
        policy.set_weights(weights, 1)
        out[name] = policy
    return out


def time_policy(policy: Policy, obs: np.ndarray, min_seconds: float, min_calls: int = 2) -> dict[str, float]:
    e = obs.shape[0]
    first = np.ones(e, bool)
    policy.act(obs, first, None, None, explore=False)  # warm-up
    calls = 0
    start, cpu_start = time.perf_counter(), time.thread_time()
    while calls < min_calls or time.perf_counter() - start < min_seconds:
        policy.act(obs, np.zeros(e, bool), None, None, explore=False)
        calls += 1
    wall, cpu = time.perf_counter() - start, time.thread_time() - cpu_start
    return {"ms_per_decision": 1e3 * wall / (e * calls), "ms_per_decision_cpu": 1e3 * cpu / (e * calls)}


def run(quick: bool = False) -> Iterator[dict]:
    from wmdist.envs.config import EnvConfig
    from wmdist.envs.factory import make_env

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        policies = _policies()
        env = make_env(EnvConfig(id="nav:tworooms"), 0)
        for envs in (1, 10):
            obs = np.stack([env.reset() for _ in range(envs)])
            for name, policy in policies.items():
                planner = policy.cfg.planner  # type: ignore[attr-defined]
                r = time_policy(policy, obs, 0.5 if quick else 5.0, 1 if quick else 2)
                yield {"case": f"{name}_E{envs}", "algo": name, "envs": envs, "horizon": planner.horizon,
                       "candidates": planner.candidates, "top_k": planner.top_k, "iterations": planner.iterations,
                       "graph_nodes": 0 if getattr(policy, "graph", None) is None else len(policy.graph.nodes),
                       **{k: round(v, 3) for k, v in r.items()}, "threads": 1}
    finally:
        torch.set_num_threads(threads)
