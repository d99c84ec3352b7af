"""The reanalyzer's searches: roots per second and peak memory, padded calls against one call
per batch.

A reanalyze batch holds a different number of acting steps every time. The search caches its
workspace ([B, nodes, latent words]) by B, so calls of an unseen size allocate afresh; the
reanalyzer therefore searches at most `max_roots` (256) roots per call, padded to a multiple
of `ROOT_BUCKET` (64). The `unpadded` case is the old path (one call of any size, up to 1,024).

Each case runs in its own process (peak RSS is per process), on the EfficientZero MinAtar
Breakout preset's network (random weights, 16 simulations, root noise on) with random 10x10
grids, one torch thread, for `calls` calls (12) of 600-960 roots each; the first two calls (numba's
compilation) are not timed. The cases alternate, `rounds` times each, so load affects both.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Iterator

PRESET = Path(__file__).parents[2] / "configs" / "efficientzero_minatar_breakout.yaml"

CHILD = r"""
import json, resource, sys, time
import numpy as np, torch
torch.set_num_threads(1)
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec
from wmdist.runtime.malloc import tune_malloc
from wmdist.runtime.roles.setup import build_algorithm

case, calls, lo, hi, preset = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
tune_malloc()  # as every role process
cfg = load_config(preset, [])
spec = env_spec(cfg.env)
re = build_algorithm(cfg, spec, 0).make_reanalyzer("cpu")
if case == "unpadded":
    re.max_roots, re.root_bucket = 1024, 1
rng = np.random.default_rng(0)
B, T = 16, 60  # a reanalyze batch: 16 windows of 50 + 10 overlap
batch = {"obs": rng.integers(0, 2, (B, T) + tuple(spec.obs_shape)).astype(np.uint8)}
rss = lambda: int(open("/proc/self/status").read().split("VmRSS:")[1].split()[0]) / 1024
roots, seconds, peak = 0, 0.0, 0.0
for i in range(calls):
    n = int(rng.integers(lo, hi + 1))
    r, c = rng.integers(0, B, n), rng.integers(0, T, n)
    t0 = time.perf_counter()
    re.search_at(batch, r, c, add_noise=True)
    if i >= 2:
        roots, seconds = roots + n, seconds + time.perf_counter() - t0
    peak = max(peak, rss())
print(json.dumps({"roots_per_s": roots / seconds, "peak_rss_mb": peak,
                  "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def measure(case: str, calls: int, roots: tuple[int, int] = (600, 960)) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, case, str(calls), *map(str, roots), str(PRESET)], capture_output=True,
                         text=True, check=True, env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"})
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> Iterator[dict]:
    # quick (the test's): a few small calls, to show the bench runs; the figures need the full one
    calls, rounds, roots = (3, 1, (40, 100)) if quick else (12, 2, (600, 960))
    for round_ in range(rounds):
        for case in ("unpadded", "padded"):
            r = measure(case, calls, roots)
            yield {"case": case, "round": round_, "calls": calls, "roots": f"{roots[0]}-{roots[1]}", "simulations": 16,
                   "roots_per_s": round(r["roots_per_s"], 1), "peak_rss_mb": round(r["peak_rss_mb"]),
                   "max_rss_mb": round(r["max_rss_mb"]), "threads": 1}
