"""Dreamer learner speed: gradient updates/s of the small V3 model on CPU, fp32 and bf16.

Model: units 256, GRU 256, 32 x 32 latents, 2-layer MLPs; batch 16 x 64; imagination of
H = 15 from all 1024 posterior states. Two action kinds: discrete (REINFORCE, dynamics run
without autograd) and continuous (gradients through the dynamics). Each case also reports
where the time goes (world model / imagination / actor / critic, from a wall-clock split
of one update) and the top ops of a torch.profiler run.
"""
from __future__ import annotations

import time
from typing import Iterator

import numpy as np
import torch

from wmdist.algos.dreamer import Dreamer, DreamerConfig
from wmdist.envs.spec import EnvSpec


def small_v3(bf16: bool) -> DreamerConfig:
    return DreamerConfig(version=3, deter=256, units=256, mlp_layers=2, stoch=32, classes=32, bf16=bf16)


def bench_spec(discrete: bool) -> EnvSpec:
    if discrete:  # CartPole-like
        return EnvSpec("bench:discrete", (4,), "float32", "vector", num_actions=2)
    return EnvSpec("bench:continuous", (5,), "float32", "vector", action_shape=(1,), action_low=(-1.0,), action_high=(1.0,))


def random_batch(spec: EnvSpec, b: int, t: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    if spec.discrete:
        action = rng.integers(0, spec.num_actions, (b, t)).astype(np.int64)
    else:
        action = rng.uniform(-1, 1, (b, t, spec.action_dim)).astype(np.float32)
    first = np.zeros((b, t), bool)
    first[:, 0] = True
    return {
        "obs": rng.normal(size=(b, t, *spec.obs_shape)).astype(np.float32),
        "action": action,
        "reward": rng.uniform(0, 1, (b, t)).astype(np.float32),
        "first": first,
        "last": np.zeros((b, t), bool),
        "terminal": np.zeros((b, t), bool),
        "mask": np.ones((b, t), bool),
        "is_weight": np.ones(b, np.float32),
    }


def _split(learner, batch) -> dict[str, float]:
    """Wall time of each phase of one update (forward + its backward), in seconds."""
    t = learner._tensors(batch)
    out = {}
    with learner._autocast():
        t0 = time.perf_counter()
        model_loss, _, start = learner.world_model_loss(t)
        t1 = time.perf_counter()
        actor_loss, critic_loss, _ = learner.ac_loss(start, learner.generator)
        t2 = time.perf_counter()
    learner.actor_opt(actor_loss)
    t3 = time.perf_counter()
    learner.critic_opt(critic_loss)
    t4 = time.perf_counter()
    learner.wm_opt(model_loss)
    t5 = time.perf_counter()
    out["world_model_fwd"] = t1 - t0
    out["imagination_and_ac_fwd"] = t2 - t1
    out["actor_bwd_step"] = t3 - t2
    out["critic_bwd_step"] = t4 - t3
    out["world_model_bwd_step"] = t5 - t4
    return out


def _top_ops(learner, batch, k: int = 8) -> list[dict]:
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        learner.update(batch)
    rows = sorted(prof.key_averages(), key=lambda e: e.self_cpu_time_total, reverse=True)[:k]
    return [{"op": r.key, "self_ms": round(r.self_cpu_time_total / 1e3, 1), "calls": r.count} for r in rows]


def run(quick: bool = False) -> Iterator[dict]:
    threads = torch.get_num_threads()
    b, t = (4, 16) if quick else (16, 64)
    updates = 2 if quick else 5
    for discrete in (True, False):
        for bf16 in (False, True):
            spec = bench_spec(discrete)
            learner = Dreamer(spec, small_v3(bf16)).make_learner()
            batch = random_batch(spec, b, t)
            learner.update(batch)  # warm-up
            t0 = time.perf_counter()
            for _ in range(updates):
                res = learner.update(batch)
            dt = (time.perf_counter() - t0) / updates
            split = _split(learner, batch)
            yield {
                "case": f"v3_small_{'discrete' if discrete else 'continuous'}_{'bf16' if bf16 else 'fp32'}",
                "actor_grad": "reinforce" if discrete else "backprop",
                "batch": f"{b}x{t}", "horizon": 15, "threads": threads, "bf16": bf16,
                "updates_per_s": round(1.0 / dt, 3), "seconds_per_update": round(dt, 3),
                "phase_seconds": {k: round(v, 3) for k, v in split.items()},
                "top_ops": _top_ops(learner, batch) if not quick else [],
                "model_loss": round(res.metrics["model_loss"], 3),
            }
