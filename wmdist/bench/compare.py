"""Compare learning benchmarks side by side: env steps to a target per seed, and every
run's greedy-eval curve in one PNG, one colour per group.

    python -m wmdist.bench.compare --target 475 --png docs/bench/reanalyze_vs_muzero.png \\
        muzero=runs/plain reanalyze=runs/reanalyze

Each GROUP=DIR names a `--runs-dir` of `wmdist.bench.learning` (run folders named
`<config>-seed<N>-<time>`). Prints one JSON line per run and one per group: the first
crossing and the sustained figures of `wmdist.bench.learning.sustained` (mean of the last
three evals at the budget, `met`, `sustained_from_env_steps`). The plot draws every seed
thinly and, per group, the seeds' mean curve with a min-max band on a common grid, against
env steps or, with `--x minutes`, against wall-clock minutes (return against wall time: an
agent that learns more per env step but runs slower per step is seen as such).
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from wmdist.bench.learning import eval_records, sustained


def runs_in(folder: Path) -> dict[int, Path]:
    """{seed: metrics.jsonl} of the newest run of each seed in a runs dir."""
    out: dict[int, Path] = {}
    for d in sorted(folder.iterdir()):
        m = re.search(r"-seed(\d+)-", d.name)
        if m and (d / "metrics.jsonl").exists():
            out[int(m.group(1))] = d / "metrics.jsonl"
    return out


def group_problem(spec: str) -> str | None:
    """Why a GROUP=DIR argument cannot be plotted, or None when it can."""
    if "=" not in spec:
        return f"expected GROUP=DIR, got {spec!r}"
    folder = Path(spec.split("=", 1)[1])
    if not folder.is_dir():
        return f"{spec}: {folder} is not a folder"
    if not runs_in(folder):
        return f"{spec}: {folder} holds no run folders named <name>-seed<N>-<time> with a metrics.jsonl"
    return None


def band(curves: list[tuple[list[float], list[float]]]) -> tuple[list[float], list[float], list[float], list[float]]:
    """(grid, mean, min, max) of several (env steps, return) curves on a common grid: the
    union of their env steps, each curve interpolated linearly only inside its own span
    (a seed counts at a grid point only where it has data on both sides or on it)."""
    import numpy as np

    curves = [(np.asarray(x, float), np.asarray(y, float)) for x, y in curves if len(x)]
    if not curves:
        return [], [], [], []
    grid = np.unique(np.concatenate([x for x, _ in curves]))
    vals = np.full((len(curves), len(grid)), np.nan)
    for i, (x, y) in enumerate(curves):
        order = np.argsort(x, kind="stable")
        x, y = x[order], y[order]
        inside = (grid >= x[0]) & (grid <= x[-1])
        vals[i, inside] = np.interp(grid[inside], x, y)
    have = ~np.isnan(vals).all(axis=0)
    grid, vals = grid[have], vals[:, have]
    return (grid.tolist(), np.nanmean(vals, axis=0).tolist(), np.nanmin(vals, axis=0).tolist(),
            np.nanmax(vals, axis=0).tolist())


X_AXES = {"env_steps": "env steps", "minutes": "wall-clock minutes"}


def curve(records: list[dict], x_axis: str) -> tuple[list[float], list[float]]:
    """(x, greedy return) of a run's eval records: x is env steps, or run time in minutes."""
    if x_axis == "minutes":
        return [r["time"] / 60.0 for r in records], [r["eval_return"] for r in records]
    return [r["env_steps"] for r in records], [r["eval_return"] for r in records]


def _mean(xs: list) -> float | None:
    xs = [x for x in xs if x is not None]
    return sum(xs) / len(xs) if xs else None


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("groups", nargs="+", metavar="GROUP=DIR")
    p.add_argument("--target", type=float, required=True)
    p.add_argument("--png", required=True)
    p.add_argument("--budget-env-steps", type=int, default=None,
                   help="judge each run on its evals up to this many env steps (default: all)")
    p.add_argument("--budget-minutes", type=float, default=None,
                   help="judge each run on its evals up to this much run time (default: all)")
    p.add_argument("--x", choices=sorted(X_AXES), default="env_steps",
                   help="the plot's x axis: env steps (default) or wall-clock minutes")
    a = p.parse_args(argv)
    budget_seconds = a.budget_minutes * 60 if a.budget_minutes is not None else None
    for spec in a.groups:  # every group is checked before anything is plotted: one line, exit 2
        problem = group_problem(spec)
        if problem:
            print(f"wmdist: error: {problem}", file=sys.stderr)
            return 2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ("-", "--", ":", "-.")  # seeds of one group: one colour, told apart by line style
    markers = (".", "x", "+", "^")  # and, past four seeds, by marker
    for gi, spec in enumerate(a.groups):
        name, folder = spec.split("=", 1)
        results, curves = [], []
        colour = colours[gi % len(colours)]
        for si, (seed, jsonl) in enumerate(sorted(runs_in(Path(folder)).items())):
            res = sustained(jsonl, a.target, a.budget_env_steps, budget_seconds)
            print(json.dumps({"group": name, "seed": seed, "target": a.target, **res}), flush=True)
            results.append(res)
            ev = eval_records(jsonl)
            curves.append(curve(ev, a.x))
            ax.plot(*curves[-1], color=colour, linestyle=styles[si % len(styles)],
                    marker=markers[si // len(styles) % len(markers)], markersize=3, linewidth=0.8, alpha=0.35,
                    label=f"{name} seed {seed}")
        grid, mean, lo, hi = band(curves)
        if grid:
            ax.fill_between(grid, lo, hi, color=colour, alpha=0.15, linewidth=0)
            ax.plot(grid, mean, color=colour, linewidth=2.2, label=f"{name} mean of {len(curves)} (band: min-max)")
        steps = [r["env_steps_to_target"] for r in results]
        reached = [x for x in steps if x is not None]
        last3 = [r["last3_mean"] for r in results if r["last3_mean"] is not None]
        sus = [r["sustained_from_env_steps"] for r in results]
        print(json.dumps({"group": name, "runs": len(steps), "reached": len(reached),
                          "mean_env_steps_to_target": sum(reached) / len(reached) if reached else None,
                          "met": sum(bool(r["met"]) for r in results),
                          "last3_mean": _mean(last3),
                          "last3_mean_min": min(last3, default=None), "last3_mean_max": max(last3, default=None),
                          "last3_means": [r["last3_mean"] for r in results],
                          "sustained_from_env_steps": sus,
                          "max_sustained_from_env_steps": max((x for x in sus if x is not None), default=None)}),
              flush=True)
    ax.axhline(a.target, color="grey", linestyle="--", linewidth=1)
    budget_x = a.budget_minutes if a.x == "minutes" else a.budget_env_steps
    if budget_x is not None:
        ax.axvline(budget_x, color="grey", linestyle=":", linewidth=1)
    ax.set_xlabel(X_AXES[a.x])
    ax.set_ylabel("greedy eval return")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    Path(a.png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.png, dpi=90)
    return 0


if __name__ == "__main__":
    sys.exit(main())
