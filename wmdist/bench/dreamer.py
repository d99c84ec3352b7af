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


def _matmul_gflops(dtype: torch.dtype, m: int = 1024, k: int = 256, n: int = 768, reps: int = 5) -> float:
    a, b = torch.randn(m, k, dtype=dtype), torch.randn(k, n, dtype=dtype)
    a @ b
    t0 = time.perf_counter()
    for _ in range(reps):
        a @ b
    return 2 * m * k * n * reps / (time.perf_counter() - t0) / 1e9


def _update_flops(learner, batch) -> float:
    """Matmul/conv FLOPs of one update as counted by torch (embedding bags are not counted)."""
    from torch.utils.flop_counter import FlopCounterMode

    with FlopCounterMode(display=False) as counter:
        learner.update(batch)
    return counter.get_total_flops()


def _time_updates(learner, batch, updates: int) -> float:
    learner.update(batch)  # warm-up
    t0 = time.perf_counter()
    for _ in range(updates):
        learner.update(batch)
    return (time.perf_counter() - t0) / updates


def run(quick: bool = False) -> Iterator[dict]:
    """Full-size fp32 cases for both action kinds, then bf16 vs fp32 side by side.

    bf16 is measured at a reduced batch (2 x 16) next to fp32 at the same batch: on CPUs
    without native bf16 matmuls (AVX2 only, like this machine's) bf16 is far slower and a
    full-size bf16 update would take minutes.
    """
    threads = torch.get_num_threads()
    b, t = (4, 16) if quick else (16, 64)
    updates = 1 if quick else 3
    for discrete in (True, False):
        spec = bench_spec(discrete)
        learner = Dreamer(spec, small_v3(False)).make_learner()
        batch = random_batch(spec, b, t)
        dt = _time_updates(learner, batch, updates)
        flops = _update_flops(learner, batch)
        split = _split(learner, batch)
        yield {
            "case": f"v3_small_{'discrete' if discrete else 'continuous'}_fp32",
            "actor_grad": "reinforce" if discrete else "backprop",
            "batch": f"{b}x{t}", "imagination_starts": b * t, "horizon": 15, "threads": threads,
            "updates_per_s": round(1.0 / dt, 3), "seconds_per_update": round(dt, 3),
            "matmul_gflop_per_update": round(flops / 1e9, 1), "achieved_gflops": round(flops / 1e9 / dt, 1),
            "phase_seconds": {k: round(v, 3) for k, v in split.items()},
            "top_ops": [] if quick else _top_ops(learner, batch),
        }
    # bf16 autocast vs fp32, side by side at a reduced batch
    sb, st = 2, 16
    spec = bench_spec(True)
    batch = random_batch(spec, sb, st)
    times = {}
    for bf16 in (False, True):
        learner = Dreamer(spec, small_v3(bf16)).make_learner()
        times[bf16] = _time_updates(learner, batch, 1)
    yield {
        "case": "v3_small_discrete_bf16_vs_fp32",
        "batch": f"{sb}x{st}", "threads": threads,
        "fp32_seconds_per_update": round(times[False], 3), "bf16_seconds_per_update": round(times[True], 3),
        "bf16_speedup": round(times[False] / times[True], 3),
        "matmul_gflops_fp32": round(_matmul_gflops(torch.float32), 1),
        "matmul_gflops_bf16": round(_matmul_gflops(torch.bfloat16, reps=1), 2),
        "cpu_has_native_bf16": bool(torch.ops.mkldnn._is_mkldnn_bf16_supported()),
    }
