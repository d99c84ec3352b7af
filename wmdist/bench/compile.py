"""Dreamer's torch.compile options side by side with the eager learner (issue 21).

The small V3 model of `wmdist bench dreamer` (units 256, GRU 256, 32x32 latents, batch 16 x 64,
H = 15 from all 1,024 starts), at the process's torch threads (the issue's setting is 2:
`OMP_NUM_THREADS=2`). Each case builds three learners with the same weights:

- `eager`: both phases on `precision: auto`, its start-up measurement run first;
- `actor_critic`: `algo.compile_actor_critic` (one graph: the H imagined steps, heads, returns and
  losses, forward and backward);
- `both`: that and `algo.compile_world_model` (one graph: encoder, the T = 64 observe steps, heads
  and the KL, forward and backward).

The compiled learners run each phase in the precision the eager learner's `auto` chose, so each
compiles once (under `auto` a compiled phase would compile in both precisions while measuring).
Their first update compiles (`*_compile_s`: inductor's on-disk cache makes a second run on the
same machine much shorter). Updates are then timed alternately so load changes hit all alike.
The compiled phases' losses and weights are checked against the eager code on the same draws in
`tests/algos/dreamer/test_dreamer_compile.py`.

Run by name only (`wmdist bench compile --json`): a cold case compiles for up to ~10 minutes.
"""
from __future__ import annotations

import time
from typing import Iterator

import torch

from wmdist.algos.dreamer import Dreamer
from wmdist.bench.dreamer import _finish_measuring, _time_side_by_side, bench_spec, random_batch, small_v3

TIMED_UPDATES = 6


def _learner(discrete: bool, **over):
    cfg = small_v3(False, **over)
    return Dreamer(bench_spec(discrete), cfg).make_learner()  # same seed: same weights


def _case(discrete: bool, updates: int) -> dict:
    spec = bench_spec(discrete)
    batch = random_batch(spec, 16, 64)
    eager = _learner(discrete, precision_world_model="auto", precision_actor_critic="auto")
    _finish_measuring(eager, batch)
    choice = dict(eager.precision.choice)
    fixed = {"precision_world_model": choice["world_model"], "precision_actor_critic": choice["actor_critic"]}
    learners = {"eager": eager,
                "actor_critic": _learner(discrete, compile_actor_critic=True, **fixed),
                "both": _learner(discrete, compile_actor_critic=True, compile_world_model=True, **fixed)}
    compile_s = {}
    for name in ("actor_critic", "both"):
        t0 = time.perf_counter()
        learners[name].update(batch)  # compiles
        compile_s[name] = time.perf_counter() - t0
    times = _time_side_by_side(learners, batch, updates)
    return {
        "case": f"compile_{'discrete' if discrete else 'continuous'}",
        "actor_grad": "reinforce" if discrete else "backprop", "batch": "16x64", "horizon": 15,
        "threads": torch.get_num_threads(), "precision": choice,
        "eager_updates_per_s": round(1.0 / times["eager"], 3),
        "actor_critic_compiled_updates_per_s": round(1.0 / times["actor_critic"], 3),
        "both_compiled_updates_per_s": round(1.0 / times["both"], 3),
        "actor_critic_speedup": round(times["eager"] / times["actor_critic"], 3),
        "both_speedup": round(times["eager"] / times["both"], 3),
        "actor_critic_compile_s": round(compile_s["actor_critic"], 1),
        "both_compile_s": round(compile_s["both"], 1),
        "timed_updates": updates, "target_updates_per_s": 2.0,
    }


def run(quick: bool = False) -> Iterator[dict]:
    for discrete in (True,) if quick else (True, False):
        yield _case(discrete, 1 if quick else TIMED_UPDATES)
