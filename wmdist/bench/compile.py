"""`algo.compile_actor_critic` side by side with the eager learner (issue 21).

The small V3 model of `wmdist bench dreamer` (units 256, GRU 256, 32x32 latents, batch 16 x 64,
H = 15 from all 1,024 starts), both phases on `precision: auto`, at the process's torch threads
(the issue's setting is 2: `OMP_NUM_THREADS=2`). Each case builds two learners with the same
weights, one with the imagination + actor-critic phase compiled (one graph: the H imagined steps,
heads, returns and losses, forward and backward), runs `auto`'s start-up measurement in each (the
compile happens in the compiled learner's warm-up update of each precision it tries), then times
updates alternately so load changes hit both alike. The compiled phase's losses and weights are
checked against the eager code on the same draws in `tests/algos/dreamer/test_dreamer_compile.py`.

Run by name only (`wmdist bench compile --json`): each case compiles for 1-3 minutes.
"""
from __future__ import annotations

import time
from typing import Iterator

import torch

from wmdist.algos.dreamer import Dreamer
from wmdist.bench.dreamer import _finish_measuring, _time_side_by_side, bench_spec, random_batch, small_v3

TIMED_UPDATES = 6


def _learner(discrete: bool, compiled: bool):
    cfg = small_v3(False, precision_world_model="auto", precision_actor_critic="auto",
                   compile_actor_critic=compiled)
    return Dreamer(bench_spec(discrete), cfg).make_learner()  # same seed: same weights


def _case(discrete: bool, updates: int) -> dict:
    spec = bench_spec(discrete)
    batch = random_batch(spec, 16, 64)
    eager, compiled = _learner(discrete, False), _learner(discrete, True)
    t0 = time.perf_counter()
    _finish_measuring(compiled, batch)
    compiled_start_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    _finish_measuring(eager, batch)
    eager_start_s = time.perf_counter() - t0
    times = _time_side_by_side({"eager": eager, "compiled": compiled}, batch, updates)
    return {
        "case": f"compile_actor_critic_{'discrete' if discrete else 'continuous'}",
        "actor_grad": "reinforce" if discrete else "backprop", "batch": "16x64", "horizon": 15,
        "threads": torch.get_num_threads(),
        "eager_updates_per_s": round(1.0 / times["eager"], 3),
        "compiled_updates_per_s": round(1.0 / times["compiled"], 3),
        "speedup": round(times["eager"] / times["compiled"], 3),
        "eager_choice": dict(eager.precision.choice), "compiled_choice": dict(compiled.precision.choice),
        # auto's start-up updates: the compiled learner's include compiling each precision it tried
        "eager_startup_s": round(eager_start_s, 1), "compiled_startup_s": round(compiled_start_s, 1),
        "timed_updates": updates, "target_updates_per_s": 2.0,
    }


def run(quick: bool = False) -> Iterator[dict]:
    for discrete in (True,) if quick else (True, False):
        yield _case(discrete, 1 if quick else TIMED_UPDATES)
