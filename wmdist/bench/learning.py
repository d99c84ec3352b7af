"""Learning benchmarks: train a preset for several seeds, find when the greedy evaluation
first reaches a target, and draw every seed's curve in one PNG.

    python -m wmdist.bench.learning configs/muzero_cartpole.yaml --seeds 0 1 2 --target 475 \
        --png docs/muzero_cartpole.png [--set key=value ...]

Prints one JSON line per seed (env steps and wall time to target, final eval) and a
summary line; these are the figures BENCHMARKS.md keeps.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from wmdist.runtime.curves import read_jsonl


def first_reaching(jsonl: Path, target: float) -> dict:
    """The first eval record whose mean return reaches `target` (and the last eval)."""
    hit, last = None, None
    for rec in read_jsonl(jsonl):
        if rec.get("kind") != "eval" or rec.get("eval_return") is None:
            continue
        last = rec
        if hit is None and rec["eval_return"] >= target:
            hit = rec
    return {"reached": hit is not None,
            "env_steps_to_target": hit["env_steps"] if hit else None,
            "seconds_to_target": hit["time"] if hit else None,
            "final_eval_return": last["eval_return"] if last else None,
            "final_env_steps": last["env_steps"] if last else None}


def plot(runs: dict[int, Path], target: float, png: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for seed, jsonl in runs.items():
        ev = [r for r in read_jsonl(jsonl) if r.get("kind") == "eval" and r.get("eval_return") is not None]
        ax.plot([r["env_steps"] for r in ev], [r["eval_return"] for r in ev], marker=".", label=f"seed {seed}")
    ax.axhline(target, color="grey", linestyle="--", linewidth=1, label=f"target {target:g}")
    ax.set_xlabel("env steps")
    ax.set_ylabel("greedy eval return")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(png, dpi=90)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--target", type=float, required=True)
    p.add_argument("--png", required=True)
    p.add_argument("--runs-dir", default="runs/bench")
    p.add_argument("--set", nargs="*", default=[])
    a = p.parse_args(argv)
    for kv in a.set:  # `--set run.dir=X` would move the runs away from where they are looked for
        if kv.startswith("run.dir="):
            a.runs_dir = kv.split("=", 1)[1]
    runs: dict[int, Path] = {}
    results = []
    for seed in a.seeds:
        name = f"{Path(a.config).stem}-seed{seed}"
        t0 = time.monotonic()
        cmd = [sys.executable, "-m", "wmdist.cli", "train", a.config, "--set", f"run.seed={seed}",
               f"run.name={name}", f"run.dir={a.runs_dir}", "replay.seed=" + str(seed), *a.set]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.monotonic() - t0
        run_dirs = sorted(Path(a.runs_dir).glob(f"{name}-*"))
        if proc.returncode != 0 or not run_dirs:
            print(json.dumps({"seed": seed, "error": proc.stderr.strip().splitlines()[-1:]}), flush=True)
            continue
        runs[seed] = run_dirs[-1] / "metrics.jsonl"
        res = {"config": a.config, "seed": seed, "target": a.target, "wall_seconds": round(wall, 1),
               "run_dir": str(run_dirs[-1]), **first_reaching(runs[seed], a.target)}
        results.append(res)
        print(json.dumps(res), flush=True)
    if runs:
        plot(runs, a.target, Path(a.png), f"{Path(a.config).stem}: greedy eval return")
    reached = [r for r in results if r["reached"]]
    print(json.dumps({"config": a.config, "seeds": a.seeds, "reached": f"{len(reached)}/{len(results)}",
                      "max_env_steps_to_target": max((r["env_steps_to_target"] for r in reached), default=None),
                      "max_seconds_to_target": max((r["seconds_to_target"] for r in reached), default=None),
                      "png": a.png}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
