"""Learning benchmarks: train a preset for several seeds, find when the greedy evaluation
first reaches a target, and draw every seed's curve in one PNG.

    python -m wmdist.bench.learning configs/muzero_cartpole.yaml --seeds 0 1 2 --target 475 \\
        --png docs/muzero_cartpole.png [--budget-env-steps N] [--budget-minutes M] [--set key=value ...]

Prints one JSON line per seed and a summary line; these are the figures BENCHMARKS.md keeps.
A run is judged on the mean of its last three evaluations at the budget (`last3_mean`,
`met`), and `sustained_from_env_steps` is the first env step from which that three-eval
mean stays at or above the target to the end of the budget; the first crossing
(`env_steps_to_target`, `reached`) is reported beside them. Each line also names the CPU.
While a seed trains, a progress line (env steps, updates, minutes, last eval) goes to stderr
every `--progress-seconds` (60). A bad config is refused in one line before any run starts.
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO

from wmdist.telemetry.curves import read_jsonl


def eval_records(jsonl: Path, budget_env_steps: float | None = None,
                 budget_seconds: float | None = None) -> list[dict]:
    """The run's eval records (kind "eval" with a return), in file order, within the budget:
    env_steps <= budget_env_steps and time <= budget_seconds where those are given."""
    out = []
    for rec in read_jsonl(jsonl):
        if rec.get("kind") != "eval" or rec.get("eval_return") is None:
            continue
        if budget_env_steps is not None and (rec.get("env_steps") is None or rec["env_steps"] > budget_env_steps):
            continue
        if budget_seconds is not None and (rec.get("time") is None or rec["time"] > budget_seconds):
            continue
        out.append(rec)
    return out


def _first_reaching(evals: list[dict], target: float) -> dict:
    hit = next((r for r in evals if r["eval_return"] >= target), None)
    last = evals[-1] if evals else None
    return {"reached": hit is not None,
            "env_steps_to_target": hit["env_steps"] if hit else None,
            "seconds_to_target": hit.get("time") if hit else None,
            "final_eval_return": last["eval_return"] if last else None,
            "final_env_steps": last["env_steps"] if last else None}


def first_reaching(jsonl: Path, target: float, budget_env_steps: float | None = None,
                   budget_seconds: float | None = None) -> dict:
    """The first eval record whose mean return reaches `target` (and the last eval)."""
    return _first_reaching(eval_records(jsonl, budget_env_steps, budget_seconds), target)


WINDOW = 3  # a run is judged on the mean of its last three evaluations


def sustained(jsonl: Path, target: float, budget_env_steps: float | None = None,
              budget_seconds: float | None = None) -> dict:
    """A run judged on a sustained mean, at the budget (evals past it are ignored).

    `last3_mean`: mean return of the last three evaluations (None with fewer than three);
    `met`: last3_mean >= target; `sustained_from_env_steps` / `_seconds`: the eval k (k >= 2,
    0-based) from which the mean of the three evals ending at every eval k..last stays
    >= target, i.e. the start of the final stretch of three-eval windows at or above the
    target (None if the last window is below it). `first_reaching`'s fields (the first
    single eval at or above the target) come beside them, over the same evals.
    """
    evals = eval_records(jsonl, budget_env_steps, budget_seconds)
    rets = [float(r["eval_return"]) for r in evals]
    means = [sum(rets[j - WINDOW + 1:j + 1]) / WINDOW for j in range(WINDOW - 1, len(rets))]
    last3 = means[-1] if means else None
    k = None  # index into `evals` of the first window end of the final run at/above target
    for j in range(len(rets) - 1, WINDOW - 2, -1):
        if means[j - WINDOW + 1] < target:
            break
        k = j
    return {**_first_reaching(evals, target),
            "budget_env_steps": budget_env_steps, "budget_seconds": budget_seconds,
            "evals": len(evals),
            "last3_mean": last3,
            "met": last3 is not None and last3 >= target,
            "sustained_from_env_steps": evals[k]["env_steps"] if k is not None else None,
            "sustained_from_seconds": evals[k].get("time") if k is not None else None}


def cpu_info(path: str = "/proc/cpuinfo") -> dict:
    """The CPU model (first "model name" line) and whether it has the bf16 instructions."""
    model, flags = None, set()
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            for line in f:
                key, _, value = line.partition(":")
                key = key.strip()
                if key == "model name" and model is None:
                    model = value.strip()
                elif key == "flags" and not flags:
                    flags = set(value.split())
                if model is not None and flags:
                    break
    except OSError:
        pass
    if model is None:
        import platform

        model = platform.processor() or platform.machine() or None
    return {"cpu": model, "cpu_avx512_bf16": "avx512_bf16" in flags, "cpu_amx_bf16": "amx_bf16" in flags}


def plot(runs: dict[int, Path], target: float, png: Path, title: str, budget_env_steps: float | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for seed, jsonl in runs.items():
        ev = [r for r in read_jsonl(jsonl) if r.get("kind") == "eval" and r.get("eval_return") is not None]
        ax.plot([r["env_steps"] for r in ev], [r["eval_return"] for r in ev], marker=".", label=f"seed {seed}")
    ax.axhline(target, color="grey", linestyle="--", linewidth=1, label=f"target {target:g}")
    if budget_env_steps is not None:
        ax.axvline(budget_env_steps, color="grey", linestyle=":", linewidth=1, label=f"budget {budget_env_steps:g} steps")
    ax.set_xlabel("env steps")
    ax.set_ylabel("greedy eval return")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(png, dpi=90)


def summary(config: str, seeds: list[int], results: list[dict], png: str) -> dict:
    """The summary line: `met` counts runs whose last-three mean at the budget reaches the
    target (the rule), `reached` those with any single eval at or above it (first crossing)."""
    reached = [r for r in results if r["reached"]]
    met = [r for r in results if r.get("met")]
    return {"config": config, "seeds": seeds, "met": f"{len(met)}/{len(results)}",
            "reached": f"{len(reached)}/{len(results)}",
            "budget_env_steps": results[0]["budget_env_steps"] if results else None,
            "budget_seconds": results[0]["budget_seconds"] if results else None,
            "last3_means": [r["last3_mean"] for r in results],
            "max_sustained_from_env_steps": max((r["sustained_from_env_steps"] for r in met
                                                 if r["sustained_from_env_steps"] is not None), default=None),
            "max_env_steps_to_target": max((r["env_steps_to_target"] for r in reached), default=None),
            "max_seconds_to_target": max((r["seconds_to_target"] for r in reached), default=None),
            "png": png}


def progress_line(seed: int, run_dir: Path | None, started: float) -> str:
    """What a running seed has done so far, read from its metrics.jsonl (torn lines skipped)."""
    minutes = (time.monotonic() - started) / 60
    last, last_eval = None, None
    for rec in read_jsonl(run_dir / "metrics.jsonl") if run_dir is not None else ():
        last = rec
        if rec.get("kind") == "eval" and rec.get("eval_return") is not None:
            last_eval = rec
    if last is None:
        return f"wmdist: seed {seed}: starting ({minutes:.1f} min)"
    line = (f"wmdist: seed {seed}: {last.get('env_steps', 0):,} env steps, {last.get('updates', 0):,} updates, "
            f"{minutes:.1f} min")
    if last_eval is not None:
        line += f", last eval {last_eval['eval_return']:.1f} at {last_eval.get('env_steps', 0):,} env steps"
    return line


class Progress:
    """Prints `progress_line` for the seed now training every `every` seconds (stderr), so an
    hour-long bench says where it is; stdout keeps only the JSON lines."""

    def __init__(self, seed: int, runs_dir: Path, name: str, every: float, out: IO[str] | None = None) -> None:
        self.seed, self.runs_dir, self.name, self.every = seed, runs_dir, name, every
        self.out = out or sys.stderr
        self.before = set(runs_dir.glob(f"{name}-*"))  # an older run of the same seed is not this one
        self.started = time.monotonic()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def _run_dir(self) -> Path | None:
        new = sorted(set(self.runs_dir.glob(f"{self.name}-*")) - self.before)
        return new[-1] if new else None

    def _loop(self) -> None:
        while not self.stop.wait(self.every):
            print(progress_line(self.seed, self._run_dir(), self.started), file=self.out, flush=True)

    def __enter__(self) -> "Progress":
        if self.every > 0:
            self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        if self.thread.is_alive():
            self.thread.join()


def config_problem(config: str, overrides: list[str], seeds: list[int]) -> str | None:
    """Why the runs this bench would start cannot start (the config with each seed), or None."""
    from wmdist.config.errors import ConfigError
    from wmdist.config.loader import load_config

    try:
        for seed in seeds:
            load_config(config, [f"run.seed={seed}", f"replay.seed={seed}", *overrides])
    except ConfigError as err:
        return str(err)
    return None


def argument_problem(target: float, budget_env_steps: int | None, budget_minutes: float | None) -> str | None:
    """A target or budget that no run can be judged against (NaN compares false with every return)."""
    if not math.isfinite(target):
        return f"--target must be a finite number, got {target}"
    if budget_env_steps is not None and budget_env_steps <= 0:
        return f"--budget-env-steps must be > 0, got {budget_env_steps}"
    if budget_minutes is not None and not (math.isfinite(budget_minutes) and budget_minutes > 0):
        return f"--budget-minutes must be a positive number, got {budget_minutes}"
    return None


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--target", type=float, required=True)
    p.add_argument("--png", required=True)
    p.add_argument("--runs-dir", default="runs/bench")
    p.add_argument("--budget-env-steps", type=int, default=None,
                   help="judge each run on its evals up to this many env steps (default: all)")
    p.add_argument("--budget-minutes", type=float, default=None,
                   help="judge each run on its evals up to this much run time (default: all)")
    p.add_argument("--set", action="extend", nargs="*", default=[])  # every `--set` counts, not the last
    p.add_argument("--progress-seconds", type=float, default=60.0,
                   help="print the running seed's env steps and last eval to stderr this often (0: never)")
    a = p.parse_args(argv)
    base, sets = Path(a.config).stem, []
    for kv in a.set:  # `--set run.dir=X` / `run.name=X` would move the runs away from where they are looked for
        if kv.startswith("run.dir="):
            a.runs_dir = kv.split("=", 1)[1]
        if kv.startswith("run.name="):  # the runs' name; each seed's run is NAME-seedS, as without it
            base = kv.split("=", 1)[1]
            continue
        sets.append(kv)
    budget_seconds = a.budget_minutes * 60 if a.budget_minutes is not None else None
    problem = argument_problem(a.target, a.budget_env_steps, a.budget_minutes) or config_problem(a.config, a.set, a.seeds)
    if problem:  # a bad config would fail every seed in turn: one line, exit 2, before any run
        print(f"wmdist: error: {problem}", file=sys.stderr)
        return 2
    cpu = cpu_info()
    runs: dict[int, Path] = {}
    results = []
    for seed in a.seeds:
        name = f"{base}-seed{seed}"
        t0 = time.monotonic()
        cmd = [sys.executable, "-m", "wmdist.cli", "train", a.config, "--set", f"run.seed={seed}",
               f"run.name={name}", f"run.dir={a.runs_dir}", "replay.seed=" + str(seed), *sets]
        with Progress(seed, Path(a.runs_dir), name, a.progress_seconds):
            proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.monotonic() - t0
        run_dirs = sorted(Path(a.runs_dir).glob(f"{name}-*"))
        error = proc.stderr.strip().splitlines()[-1:] if proc.returncode != 0 else None
        if not run_dirs or not (run_dirs[-1] / "metrics.jsonl").exists():
            print(json.dumps({"seed": seed, "error": error or ["no run directory was written"]}), flush=True)
            continue
        # a run that failed after start-up is still judged on what it logged, with its error beside it
        runs[seed] = run_dirs[-1] / "metrics.jsonl"
        res = {"config": a.config, "seed": seed, "target": a.target, "wall_seconds": round(wall, 1),
               "run_dir": str(run_dirs[-1]), **sustained(runs[seed], a.target, a.budget_env_steps, budget_seconds),
               **cpu}
        if error:  # it stopped before its budget: never counted as met, whatever it logged
            res.update(error=error, met=False)
        results.append(res)
        print(json.dumps(res), flush=True)
    if runs:
        plot(runs, a.target, Path(a.png), f"{Path(a.config).stem}: greedy eval return", a.budget_env_steps)
    print(json.dumps(summary(a.config, a.seeds, results, a.png)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
