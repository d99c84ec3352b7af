"""PlaNet's CEM planner speed: decisions per second, and the share of time in the model.

Cases: the paper's planner (H 12, J 1000, K 100, I 10) and the state preset's
(configs/planet_dmc_cartpole_swingup.yaml), each for E = 1 and E = 8 envs planned in one
batched call, on PlaNet's world model at the paper's sizes (GRU 200, Gaussian 30, MLPs of
200; randomly initialised: the cost does not depend on the weights) for cartpole-swingup
from state (5-d observations, 1-d actions), one torch thread (what a collector gets).
`decisions_per_s` = E x planning calls / wall time (one decision = one env's action);
`model_share` = the share of that time inside the model's rollouts (the score function),
the rest is the planner's sampling, top-K and refits; `ms_per_call` = one batched call;
`env_steps_45min` = the env steps 45 minutes of such planning would take. `*_cpu` fields
divide by this thread's CPU time instead of wall time: what planning costs when the machine
is shared with other processes, which only deschedule it.

One more case, `learner_precision`: the state preset's learner (batch 50 x 50) updating in
fp32 and in bf16, interleaved on one thread, as the preset's `precision: auto` compares them
at start-up; where the CPU has no native bf16 it is reported and not timed (it is far slower).
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Iterator

import torch

from wmdist.algos.planet import PlaNet, PlaNetConfig
from wmdist.algos.planet.planning import reward_sum_fn
from wmdist.envs.spec import EnvSpec
from wmdist.search.cem import CEMConfig, cem_plan

PRESET = Path(__file__).parents[2] / "configs" / "planet_dmc_cartpole_swingup.yaml"
SPEC = EnvSpec("bench:cartpole-swingup", (5,), "float32", "vector", action_shape=(1,), action_low=(-1.0,),
               action_high=(1.0,))


def preset_planner() -> CEMConfig:
    from wmdist.config.loader import load_config

    return load_config(str(PRESET)).algo.planner


def time_planner(planner: CEMConfig, envs: int, min_seconds: float, min_calls: int = 2, seed: int = 0) -> dict[str, float]:
    """Plan repeatedly for `envs` rows from random states; wall time per call and its model share."""
    algo = PlaNet(SPEC, PlaNetConfig(planner=planner), seed)
    wm = algo.make_policy().wm
    gen = torch.Generator().manual_seed(seed)
    h = torch.randn(envs, wm.cfg.deter, generator=gen)
    z = wm.rssm.initial(envs)[1]
    z.sample = torch.randn(envs, wm.cfg.stoch, generator=gen)
    low, high = -torch.ones(envs, SPEC.action_dim), torch.ones(envs, SPEC.action_dim)
    score = reward_sum_fn(wm, h, z, gen)
    in_model = [0.0]

    def timed(actions: torch.Tensor) -> torch.Tensor:
        t0 = time.perf_counter()
        out = score(actions)
        in_model[0] += time.perf_counter() - t0
        return out

    cem_plan(timed, low, high, planner, gen)  # warm-up
    in_model[0], calls = 0.0, 0
    start, cpu_start = time.perf_counter(), time.thread_time()
    while calls < min_calls or time.perf_counter() - start < min_seconds:
        cem_plan(timed, low, high, planner, gen)
        calls += 1
    wall, cpu = time.perf_counter() - start, time.thread_time() - cpu_start
    return {"ms_per_call": 1e3 * wall / calls, "decisions_per_s": envs * calls / wall, "model_share": in_model[0] / wall,
            "ms_per_call_cpu": 1e3 * cpu / calls, "decisions_per_cpu_s": envs * calls / cpu}


def learner_precision(updates: int) -> dict:
    """Seconds per update of the state preset's learner in fp32 and in bf16, interleaved."""
    from wmdist.algos.dreamer.precision import native_bf16
    from wmdist.bench.dreamer import _time_side_by_side, random_batch
    from wmdist.config.loader import load_config

    cfg = load_config(str(PRESET))
    row = {"case": "learner_precision", "batch": f"{cfg.learner.batch_size}x{cfg.replay.seq_len}",
           "native_bf16": native_bf16(torch.device("cpu")), "threads": 1}
    if not row["native_bf16"]:
        return row
    learners = {p: PlaNet(SPEC, dataclasses.replace(cfg.algo, precision=p), 0).make_learner() for p in ("fp32", "bf16")}
    batch = random_batch(SPEC, cfg.learner.batch_size, cfg.replay.seq_len)
    times = _time_side_by_side(learners, batch, updates)
    return {**row, "seconds_per_update_fp32": round(times["fp32"], 4), "seconds_per_update_bf16": round(times["bf16"], 4),
            "bf16_speedup": round(times["fp32"] / times["bf16"], 2)}


def run(quick: bool = False) -> Iterator[dict]:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        paper = CEMConfig(horizon=12, candidates=1000, top_k=100, iterations=10)
        for name, planner in (("paper", paper), ("preset", preset_planner())):
            for envs in (1, 8):
                r = time_planner(planner, envs, 0.5 if quick else 5.0, 1 if quick else 2)
                yield {
                    "case": f"{name}_E{envs}", "horizon": planner.horizon, "candidates": planner.candidates,
                    "top_k": planner.top_k, "iterations": planner.iterations, "envs": envs,
                    **{k: round(v, 4) for k, v in r.items()},
                    "env_steps_45min": int(r["decisions_per_s"] * 45 * 60),
                    "env_steps_45min_cpu": int(r["decisions_per_cpu_s"] * 45 * 60), "threads": 1,
                }
        yield learner_precision(1 if quick else 6)
    finally:
        torch.set_num_threads(threads)
