"""Compare learning benchmarks side by side: env steps to a target per seed, and every
run's greedy-eval curve in one PNG, one colour per group.

    python -m wmdist.bench.compare --target 475 --png docs/bench/reanalyze_vs_muzero.png \\
        muzero=runs/plain reanalyze=runs/reanalyze

Each GROUP=DIR names a `--runs-dir` of `wmdist.bench.learning` (run folders named
`<config>-seed<N>-<time>`). Prints one JSON line per run and one per group.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from wmdist.bench.learning import first_reaching
from wmdist.runtime.curves import read_jsonl


def runs_in(folder: Path) -> dict[int, Path]:
    """{seed: metrics.jsonl} of the newest run of each seed in a runs dir."""
    out: dict[int, Path] = {}
    for d in sorted(folder.iterdir()):
        m = re.search(r"-seed(\d+)-", d.name)
        if m and (d / "metrics.jsonl").exists():
            out[int(m.group(1))] = d / "metrics.jsonl"
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("groups", nargs="+", metavar="GROUP=DIR")
    p.add_argument("--target", type=float, required=True)
    p.add_argument("--png", required=True)
    a = p.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ("-", "--", ":", "-.")  # seeds of one group: one colour, told apart by line style
    markers = (".", "x", "+", "^")  # and, past four seeds, by marker
    for gi, spec in enumerate(a.groups):
        if "=" not in spec:
            print(f"wmdist: expected GROUP=DIR, got {spec!r}", file=sys.stderr)
            return 2
        name, folder = spec.split("=", 1)
        steps = []
        for si, (seed, jsonl) in enumerate(sorted(runs_in(Path(folder)).items())):
            res = first_reaching(jsonl, a.target)
            print(json.dumps({"group": name, "seed": seed, "target": a.target, **res}), flush=True)
            steps.append(res["env_steps_to_target"])
            ev = [r for r in read_jsonl(jsonl) if r.get("kind") == "eval" and r.get("eval_return") is not None]
            ax.plot([r["env_steps"] for r in ev], [r["eval_return"] for r in ev], color=colours[gi % len(colours)],
                    linestyle=styles[si % len(styles)], marker=markers[si // len(styles) % len(markers)], alpha=0.8, label=f"{name} seed {seed}")
        reached = [s for s in steps if s is not None]
        print(json.dumps({"group": name, "runs": len(steps), "reached": len(reached),
                          "mean_env_steps_to_target": sum(reached) / len(reached) if reached else None}), flush=True)
    ax.axhline(a.target, color="grey", linestyle="--", linewidth=1)
    ax.set_xlabel("env steps")
    ax.set_ylabel("greedy eval return")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    Path(a.png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.png, dpi=90)
    return 0


if __name__ == "__main__":
    sys.exit(main())
