"""torch.compile on the Dreamer learner's phases, side by side with eager (issue 21).

The small V3 model of `wmdist bench dreamer` (units 256, GRU 256, 32x32 latents, batch 16 x 64,
H = 15 from all 1,024 starts), bf16 autocast. Each case builds two learners with the same
weights, wraps one phase of the second in `torch.compile` (the actor-critic loss: imagination,
heads, returns; or the world-model loss: encoder, the 64-step observe loop, decoder), and
times updates alternately, one torch thread. It reports the compile time (the first two
updates) and, as the check against the obviously-correct reference, the relative difference
of every loss between the two learners after the same updates on the same batch.

Run by name only (`wmdist bench compile --json`): the three compiles take ~2 minutes each.
"""
from __future__ import annotations

import time
from typing import Iterator

import torch

from wmdist.algos.dreamer import Dreamer
from wmdist.bench.dreamer import bench_spec, random_batch, small_v3

TIMED_UPDATES = 5
CASES = (("discrete", "actor_critic"), ("continuous", "actor_critic"), ("discrete", "world_model"))
LOSSES = ("model_loss", "actor_loss", "critic_loss")


def _median(xs: list[float]) -> float:
    return sorted(xs)[len(xs) // 2]


def _case(actions: str, phase: str) -> dict:
    spec = bench_spec(actions == "discrete")
    batch = random_batch(spec, 16, 64)
    eager, compiled = (Dreamer(spec, small_v3(True)).make_learner() for _ in range(2))  # same seed: same weights
    if phase == "actor_critic":
        compiled.ac_loss = torch.compile(compiled.ac_loss)
    else:
        compiled.world_model_loss = torch.compile(compiled.world_model_loss)
    t0 = time.perf_counter()
    for _ in range(2):
        compiled.update(batch)
    compile_s = time.perf_counter() - t0
    for _ in range(2):
        eager.update(batch)
    te, tc = [], []
    for _ in range(TIMED_UPDATES):
        t0 = time.perf_counter()
        me = eager.update(batch).metrics
        te.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        mc = compiled.update(batch).metrics
        tc.append(time.perf_counter() - t0)
    diff = {k: abs(mc[k] - me[k]) / max(abs(me[k]), 1e-6) for k in LOSSES}
    return {"case": f"compile_{phase}_{actions}", "eager_s_per_update": round(_median(te), 4),
            "compiled_s_per_update": round(_median(tc), 4), "speedup": round(_median(te) / _median(tc), 3),
            "compile_seconds": round(compile_s, 1), "loss_rel_diff_max": round(max(diff.values()), 5),
            "updates_compared": 2 + TIMED_UPDATES, "threads": torch.get_num_threads()}


def run(quick: bool = False) -> Iterator[dict]:
    torch.set_num_threads(1)
    for actions, phase in CASES[:1] if quick else CASES:
        yield _case(actions, phase)
