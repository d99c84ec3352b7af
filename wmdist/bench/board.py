"""Board-game benchmark: a trained run's agent against the run's evaluation opponent.

    python -m wmdist.bench.board RUN_DIR --games 200 --png docs/bench/muzero_tictactoe.png \
        --lines-png docs/bench/muzero_tictactoe_lines.png

Plays `games` games with the run's latest checkpoint (half as first player, half as
second) against the opponent the run evaluated with: tic-tac-toe's exact solver (a random
optimal move, so games differ) or connect four's UCT search (`eval.opponent_rollouts` random
rollouts per move). Prints one JSON line with the counts (and `won_fraction`); for
tic-tac-toe it also judges the checkpoint over every opponent line. `--png` plots the
in-training evaluations against env steps: games lost to the solver (tic-tac-toe) or the
share of games won (connect four); `--lines-png` the lines lost per evaluation
(`eval_lost_lines`) against wall-clock minutes; `--versus JSONL` plots connect four's share
won against minutes beside other runs' curves.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from wmdist.telemetry.curves import read_jsonl


def _plot(xs: list, ys: list, xlabel: str, ylabel: str, title: str, png: Path, symlog: bool = False) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(xs, ys, marker=".")
    if symlog:
        ax.set_yscale("symlog")  # hundreds early, a handful late: zero must stay visible
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(png, dpi=90)


def plot_losses(metrics: Path, games_per_eval: int, png: Path, title: str) -> None:
    """Games lost per evaluation: against a perfect opponent the mean outcome is -losses / games."""
    # Evaluations against the opponent log eval_min (older runs' self-play evaluations did not).
    ev = [r for r in read_jsonl(metrics) if r.get("kind") == "eval" and r.get("eval_min") is not None]
    _plot([r["env_steps"] for r in ev], [round(-r["eval_return"] * games_per_eval) for r in ev],
          "env steps", f"games lost of {games_per_eval}", title, png)


def plot_won(metrics: Path, png: Path, title: str) -> None:
    """Share of games won per evaluation (`eval_won`; runs from before it was logged: the
    mean outcome, which equals 2 x won - 1 when no game is drawn)."""
    ev = [r for r in read_jsonl(metrics) if r.get("kind") == "eval" and r.get("eval_min") is not None]
    if ev and all(r.get("eval_won") is not None for r in ev):
        _plot([r["env_steps"] for r in ev], [r["eval_won"] for r in ev], "env steps", "share of games won", title, png)
    else:
        _plot([r["env_steps"] for r in ev], [r["eval_return"] for r in ev], "env steps",
              "mean outcome (+1 won, 0 drawn, -1 lost)", title, png)


def plot_won_minutes(metrics: Path, versus: Path, png: Path, title: str, label: str) -> None:
    """Share of games won per evaluation against wall-clock minutes, this run beside the
    curves in `versus` (JSON lines with `net`, `minutes` and `won`, as docs/bench keeps them)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series: dict[str, tuple[list, list]] = {}
    for r in read_jsonl(versus):
        if r.get("won") is not None:
            xs, ys = series.setdefault(r["net"], ([], []))
            xs.append(r["minutes"])
            ys.append(r["won"])
    ev = [r for r in read_jsonl(metrics) if r.get("kind") == "eval" and r.get("eval_won") is not None]
    series[label] = ([r["time"] / 60.0 for r in ev], [r["eval_won"] for r in ev])
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for name, (xs, ys) in series.items():
        ax.plot(xs, ys, marker=".", label=name)
    ax.set_xlabel("wall-clock minutes")
    ax.set_ylabel("share of games won")
    ax.set_ylim(-0.03, 1.03)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(png, dpi=90)


def opponent_name(game: str, rollouts: int) -> str:
    return "the exact solver" if game == "tictactoe" else f"UCT ({rollouts} rollouts per move)"


def plot_lost_lines(metrics: Path, png: Path, title: str) -> None:
    """Opponent lines lost per in-training evaluation (the whole-tree judge) against minutes."""
    ev = [r for r in read_jsonl(metrics) if r.get("kind") == "eval" and r.get("eval_lost_lines") is not None]
    _plot([r["time"] / 60.0 for r in ev], [r["eval_lost_lines"] for r in ev],
          "wall-clock minutes", "opponent lines lost (both sides)", title, png, symlog=True)


def main(argv: list[str] | None = None) -> int:
    from wmdist.config.errors import ConfigError

    try:
        return _main(argv)
    except ConfigError as err:  # a bad run directory or --simulations: one line, as `wmdist eval`
        print(f"wmdist: error: {err}", file=sys.stderr)
        return 2


def _main(argv: list[str] | None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir")
    p.add_argument("--games", type=int, default=200)
    p.add_argument("--png", default=None)
    p.add_argument("--lines-png", default=None, help="plot the in-training judge's lost lines per evaluation")
    p.add_argument("--versus", default=None, help="with --png, connect four: plot games won against minutes beside "
                                                  "the curves in this JSON-lines file (net, minutes, won)")
    p.add_argument("--simulations", type=int, default=0,
                   help="search simulations per move (default: the run's eval.num_simulations, else its search's)")
    a = p.parse_args(argv)
    from wmdist.envs.factory import make_env
    from wmdist.runtime.board_eval import default_opponent, judge_lines, play_games, summary
    from wmdist.runtime.evaluate import load_run
    from wmdist.runtime.roles.setup import build_algorithm, evaluation_config

    cfg, spec, algo, version, weights, ckpt = load_run(a.run_dir, [f"eval.num_simulations={a.simulations}"]
                                                       if a.simulations else None)
    if cfg.eval.num_simulations:
        algo = build_algorithm(evaluation_config(cfg), spec, cfg.run.seed + 31_337)
    if spec.players != 2:
        print(f"wmdist: {a.run_dir} is not a board-game run", file=sys.stderr)
        return 2
    policy = algo.make_policy("cpu")
    policy.set_weights(weights, version)
    env = make_env(cfg.env, cfg.run.seed)
    game, rollouts = env.game.name, cfg.eval.opponent_rollouts
    counts = summary(play_games(policy, env, a.games, default_opponent(env, cfg.run.seed + 1, rollouts)))
    lost = counts["lost_p0"] + counts["lost_p1"]
    won = counts["won_p0"] + counts["won_p1"]
    lines = judge_lines(policy, env) if game == "tictactoe" else {}
    sims = cfg.eval.num_simulations or getattr(getattr(cfg.algo, "search", None), "num_simulations", None)
    print(json.dumps({"env": cfg.env.id, "checkpoint": ckpt.name, "weights_version": version, "simulations": sims,
                      "opponent": opponent_name(game, rollouts), "games": a.games, **counts, "won": won,
                      "won_fraction": won / a.games, "lost": lost, "never_loses": lost == 0, **lines}), flush=True)
    if a.png and game == "tictactoe":
        plot_losses(Path(a.run_dir) / "metrics.jsonl", cfg.eval.episodes, Path(a.png),
                    f"{cfg.env.id}: games lost to the exact solver per evaluation")
    elif a.png and a.versus:
        label = f"this run ({getattr(cfg.algo, 'tree_model', 'learned')} model in the tree)"
        plot_won_minutes(Path(a.run_dir) / "metrics.jsonl", Path(a.versus), Path(a.png),
                         f"{cfg.env.id}: games won against {opponent_name(game, rollouts)}", label)
    elif a.png:
        plot_won(Path(a.run_dir) / "metrics.jsonl", Path(a.png),
                 f"{cfg.env.id}: games won against {opponent_name(game, rollouts)} per evaluation")
    if a.lines_png:
        plot_lost_lines(Path(a.run_dir) / "metrics.jsonl", Path(a.lines_png),
                        f"{cfg.env.id}: opponent lines lost per evaluation (every line judged)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
