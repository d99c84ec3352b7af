"""World Models' controller search: CMA-ES generations per minute with 1 and 2 evaluation actors.

Each generation asks `popsize` candidates, the pool (`worldmodels.pool.EvalPool` over Ray actors
of the `wm_eval` role's class) scores each on `rollouts` dream rollouts of M, and CMA-ES is told.
Sizes are the Take Cover preset's (configs/worldmodels_doom_takecover.yaml: z 32, LSTM 256,
5 Gaussians, 3 actions, population 16, 8 rollouts); M is randomly initialised with its done head
biased to "never done", so every rollout runs the full `dream_steps` and the cost per generation
is fixed. One torch thread per actor (what a 2-core machine gives). Cases: actors = 0 (the learner
dreams itself, no Ray), 1 and 2 on a local Ray instance with 2 CPUs, and 2 on a simulated
multi-node cluster (`ray.cluster_utils.Cluster`: a head and two worker nodes of 1 CPU on this
machine), placed one per worker node by a custom resource (`algo.eval_actor_resources`), with the
nodes they ran on (`nodes`).
`generations_per_min`; `dream_steps_per_s` = candidates x rollouts x steps per second.

Then the real game (the CarRacing preset's search, `train_in: real`): one evaluation actor, in
this process, scores 8 candidates on CarRacing-v3 episodes, one episode at a time (`real_envs:
1`) and 8 in lockstep (`real_envs: 8`, one batched V and M call per step), alternating, two
rounds: `real_steps_per_s` and `over_one_at_a_time`.
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
CAR_PRESET = PRESET.with_name("worldmodels_carracing.yaml")
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
    if started:  # a cluster of its own needs this process off any other Ray instance
        yield {"actors": 2, "cluster_nodes": 3, **common, **cluster_case(cfg, min_seconds)}
    yield from real_cases(quick)


def cluster_case(cfg, min_seconds: float) -> dict:
    """Two evaluation actors spread over two worker nodes of a local multi-node cluster."""
    import ray
    from ray.cluster_utils import Cluster

    from wmdist.algos.worldmodels.worker import EvalWorker

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    workers = [cluster.add_node(num_cpus=1, resources={"eval_node": 1}) for _ in range(2)]
    ray.init(address=cluster.address, log_to_driver=False, configure_logging=False)
    try:
        actor = ray.remote(EvalWorker).options(num_cpus=1, resources={"eval_node": 1}, max_restarts=-1, max_task_retries=0)
        handles = [actor.remote(None, SPEC, i, 1, algo_config=cfg) for i in range(2)]
        nodes = ray.get([h.node_id.remote() for h in handles])
        worker_ids = {w.node_id for w in workers}
        out = time_search(cfg, handles, min_seconds)
        return {**out, "nodes": len(set(nodes)), "on_worker_nodes": set(nodes) <= worker_ids}
    finally:
        ray.shutdown()
        cluster.shutdown()


def real_cases(quick: bool) -> Iterator[dict]:
    """Real CarRacing rollouts scored one at a time against 8 in lockstep (random V and M)."""
    import dataclasses

    from wmdist.algos.worldmodels.models import build_vae
    from wmdist.algos.worldmodels.worker import EvalWorker
    from wmdist.config.loader import load_config
    from wmdist.envs.factory import make_env

    run_cfg = load_config(str(CAR_PRESET))
    steps = 20 if quick else 150
    spec = make_env(run_cfg.env, seed=0).spec
    torch.manual_seed(0)
    base = run_cfg.algo
    model = {**to_numpy(build_vae(base, spec), "vae"), **to_numpy(build_rnn(base, spec), "rnn"),
             "bank_mu": np.zeros((1, base.z_dim), np.float32), "bank_logvar": np.zeros((1, base.z_dim), np.float32)}
    p = num_params(spec, base.z_dim, base.rnn_hidden, base.controller_h)
    cands = np.random.default_rng(0).normal(0, base.sigma0, (8, p)).astype(np.float32)  # [8, P]
    workers = {}
    for width in (1, 8):
        cfg = dataclasses.replace(base, real_envs=width, real_max_steps=steps)
        workers[width] = EvalWorker(run_cfg, spec, 0, 1, algo_config=cfg)
        workers[width].load_model(1, model)
        workers[width].evaluate(1, cands[:1], np.array([0]), "real")  # warm-up: envs built, first render
    for rnd in range(2):
        rate: dict[int, float] = {}  # this round's real steps/s per width
        for width in (1, 8):
            t0 = time.perf_counter()
            workers[width].evaluate(1, cands, np.array([rnd + 1]), "real")
            rate[width] = len(cands) * steps / (time.perf_counter() - t0)
            yield {"case": "real", "env": run_cfg.env.id, "round": rnd, "real_envs": width, "candidates": len(cands),
                   "steps": steps, "params": p, "real_steps_per_s": round(rate[width], 1),
                   "over_one_at_a_time": round(rate[width] / rate[1], 3)}
