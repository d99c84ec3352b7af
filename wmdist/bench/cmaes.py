"""World Models' controller search: CMA-ES generations per minute with 1 and 2 evaluation actors.

Each generation asks `popsize` candidates, the pool (`worldmodels.pool.EvalPool` over Ray actors
of the `wm_eval` role's class) scores each on `rollouts` dream rollouts of M, and CMA-ES is told.
Sizes are the Take Cover preset's (configs/worldmodels_doom_takecover.yaml: z 32, LSTM 256,
5 Gaussians, 3 actions, population 16, 8 rollouts); M is randomly initialised with its done head
biased to "never done", so every rollout runs the full `dream_steps` and the cost per generation
is fixed. One torch thread per actor (what a 2-core machine gives). Cases: actors = 0 (the learner
dreams itself, no Ray), 1 and 2 on a local Ray instance with 2 CPUs.
`generations_per_min`; `dream_steps_per_s` = candidates x rollouts x steps per second.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Iterator

import numpy as np
import torch

from wmdist.algos.worldmodels.cmaes import CMAES
from wmdist.algos.worldmodels.controller import num_params
from wmdist.algos.worldmodels.models import build_rnn, to_numpy
from wmdist.algos.worldmodels.pool import EvalPool
from wmdist.envs.spec import EnvSpec

PRESET = Path(__file__).parents[2] / "configs" / "worldmodels_doom_takecover.yaml"
SPEC = EnvSpec("bench:takecover", (64, 64, 3), "uint8", "image", num_actions=3)


def _model(cfg) -> dict[str, np.ndarray]:
    torch.manual_seed(0)
    rnn = build_rnn(cfg, SPEC)
    with torch.no_grad():
        rnn.done.bias.fill_(-50.0)  # never done: every rollout is dream_steps long
    rng = np.random.default_rng(0)
    return {**to_numpy(rnn, "rnn"), "bank_mu": rng.standard_normal((64, cfg.z_dim)).astype(np.float32),
            "bank_logvar": np.full((64, cfg.z_dim), -2.0, np.float32)}


def time_search(cfg, handles: list, min_seconds: float, min_generations: int = 2) -> dict[str, float]:
    pool = EvalPool(handles, shares_per_actor=1)  # one batched dream per actor, as the learner does
    es = CMAES(num_params(SPEC, cfg.z_dim, cfg.rnn_hidden), cfg.popsize, cfg.sigma0, seed=0)
    model = _model(cfg)
    seeds = np.arange(cfg.rollouts)
    es.step(lambda x: pool.evaluate(x, seeds, 1, lambda: model))  # warm-up: the actors get the model
    gens, start = 0, time.perf_counter()
    while gens < min_generations or time.perf_counter() - start < min_seconds:
        es.step(lambda x: pool.evaluate(x, seeds, 1, lambda: model))
        gens += 1
    wall = time.perf_counter() - start
    return {"generations": gens, "seconds": wall, "generations_per_min": 60.0 * gens / wall,
            "dream_steps_per_s": gens * cfg.popsize * cfg.rollouts * cfg.dream_max_steps / wall}


def run(quick: bool = False) -> Iterator[dict]:
    import dataclasses

    import ray

    from wmdist.algos.worldmodels.worker import EvalWorker
    from wmdist.config.loader import load_config
    from wmdist.runtime.calls import LocalHandle

    cfg = load_config(str(PRESET)).algo
    cfg = dataclasses.replace(cfg, dream_max_steps=50 if quick else 300)
    min_seconds = 3.0 if quick else 20.0
    torch.set_num_threads(1)
    common = {"popsize": cfg.popsize, "rollouts": cfg.rollouts, "dream_steps": cfg.dream_max_steps,
              "params": num_params(SPEC, cfg.z_dim, cfg.rnn_hidden)}
    yield {"actors": 0, **common, **time_search(cfg, [LocalHandle(EvalWorker(None, SPEC, 0, 1, algo_config=cfg))],
                                                min_seconds)}
    started = not ray.is_initialized()
    if started:
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        for n in (1, 2):
            actor = ray.remote(EvalWorker).options(num_cpus=1, max_restarts=-1, max_task_retries=0)
            handles = [actor.remote(None, SPEC, i, 1, algo_config=cfg) for i in range(n)]
            ray.get([h.ping.remote() for h in handles])
            try:
                yield {"actors": n, **common, **time_search(cfg, handles, min_seconds)}
            finally:
                for h in handles:
                    ray.kill(h)
    finally:
        if started:
            ray.shutdown()
