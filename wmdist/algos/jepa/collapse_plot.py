"""Runs of the collapse ablation side by side: what the learner logged about its embeddings
(their mean per-dimension std, effective rank and SIGReg statistic) and the evaluator's
success, against learner updates, one colour per run.

    python -m wmdist.algos.jepa.collapse_plot --png OUT.png sigreg=RUN_DIR no-sigreg=RUN_DIR

A collapse to a point shows in the std (scale), not in the effective rank, which is blind to
scale: a shrinking cloud keeps its shape.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from wmdist.telemetry.curves import read_jsonl

PANELS = (("loss/embed_std", "embedding std (mean over dims)", True),
          ("loss/effective_rank", "effective rank", False),
          ("loss/sigreg", "SIGReg statistic", True),
          ("eval_return", "success (evaluator)", False))


def series(jsonl: Path, key: str) -> tuple[list[float], list[float]]:
    """(updates, value) of every record that has both."""
    xs, ys = [], []
    for rec in read_jsonl(jsonl):
        if rec.get("updates") is not None and isinstance(rec.get(key), (int, float)):
            xs.append(float(rec["updates"]))
            ys.append(float(rec[key]))
    return xs, ys


def run_problem(spec: str) -> str | None:
    """Why a LABEL=RUN_DIR argument cannot be plotted, or None when it can."""
    if "=" not in spec:
        return f"expected LABEL=RUN_DIR, got {spec!r}"
    folder = Path(spec.split("=", 1)[1])
    if not (folder / "metrics.jsonl").is_file():
        return f"{spec}: {folder} has no metrics.jsonl (not a run directory)"
    if not series(folder / "metrics.jsonl", "loss/embed_std")[0]:
        return f"{spec}: {folder}/metrics.jsonl has no loss/embed_std (not a JEPA run, or no update logged yet)"
    return None


def plot(runs: dict[str, Path], png: str) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 3.2))
    axes = fig.subplots(1, len(PANELS))
    for ax, (key, title, log) in zip(axes, PANELS):
        for label, folder in runs.items():
            xs, ys = series(folder / "metrics.jsonl", key)
            ax.plot(xs, ys, marker="o" if key == "eval_return" else None, ms=3, lw=1.2, label=label)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("learner updates", fontsize=8)
        if log:
            ax.set_yscale("log")
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m wmdist.algos.jepa.collapse_plot", description=__doc__.split("\n\n")[0])
    p.add_argument("--png", required=True)
    p.add_argument("runs", nargs="+", help="LABEL=RUN_DIR")
    args = p.parse_args(argv)
    for spec in args.runs:
        problem = run_problem(spec)
        if problem:
            print(f"collapse_plot: {problem}", file=sys.stderr)
            return 2
    plot({s.split("=", 1)[0]: Path(s.split("=", 1)[1]) for s in args.runs}, args.png)
    print(f"collapse_plot: wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
