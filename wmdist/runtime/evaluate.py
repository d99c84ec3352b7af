"""`wmdist eval RUN_DIR` and `wmdist dream RUN_DIR`: load a run's latest checkpoint and
play greedy episodes (board games: against the exact solver or a human), or write the
world model's open-loop prediction video."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import IO, Callable

import numpy as np

from wmdist.algos.base import CHECKS_DREAM, PLOTS_EMBEDDINGS, PREDICTS_OBSERVATIONS
from wmdist.config.errors import ConfigError, mismatch_line
from wmdist.runtime import checkpoint as ck
from wmdist.runtime.board_eval import default_opponent, greedy_action, judge_lines, play_games
from wmdist.runtime.roles.setup import build_algorithm, evaluation_config
from wmdist.runtime.train import env_spec_or_error, load_run_config


def load_run(run_dir: str, overrides: list[str] | None = None):
    cfg = load_run_config(run_dir, overrides)
    ckpt = ck.latest_checkpoint(run_dir)
    if ckpt is None:
        raise ConfigError(f"{run_dir} has no checkpoint yet")
    spec = env_spec_or_error(cfg)
    algo = build_algorithm(cfg, spec, cfg.run.seed + 31_337)
    try:
        version, weights = ck.load_weights(ckpt)
    except Exception as err:  # noqa: BLE001 - a damaged or hand-edited file: one line, not a traceback
        raise ConfigError(ck.unreadable_message(ckpt, err)) from None
    try:  # a config.yaml edited after training (another width, another algorithm) no longer fits the weights
        algo.make_policy("cpu").set_weights(weights, version)
    except (RuntimeError, ValueError, KeyError) as err:
        raise ConfigError(f"{ckpt} does not fit the model {Path(run_dir) / 'config.yaml'} describes "
                          f"({mismatch_line(err)}); was config.yaml edited after training?") from None
    return cfg, spec, algo, version, weights, ckpt


def check_output_path(path: str | None, flag: str) -> None:
    """An output file whose folder is missing fails before the episodes are played, not after."""
    if path is None:
        return
    folder = Path(path).expanduser().resolve().parent
    if not folder.is_dir():
        raise ConfigError(f"{flag} {path}: no such folder {folder}")
    if Path(path).is_dir():
        raise ConfigError(f"{flag} {path} is a folder; give a file name")


def _human(env, out: IO[str]) -> Callable[[object], int]:
    def ask(_state) -> int:
        img = np.asarray(env.state.board).reshape(env.game.rows, env.game.cols)
        for row in img:
            print(" ".join(".XO"[c] for c in row), file=out)
        legal = np.flatnonzero(env.legal_actions())
        while True:
            raw = input(f"your move {legal.tolist()}: ").strip()
            if raw.isdigit() and int(raw) in legal:
                return int(raw)
            print("not a legal move", file=out)
    return ask


def episode_progress(episodes: int, every_seconds: float, err: IO[str]) -> Callable[[list[float]], None]:
    """An `on_episode` callback that prints 'N/M episodes, mean R' to `err` at most every `every_seconds`
    (and at the last episode), so a 100-episode evaluation of a long game says where it is."""
    last = [time.monotonic()]

    def report(returns: list[float]) -> None:
        now = time.monotonic()
        if now - last[0] >= every_seconds or len(returns) == episodes:
            last[0] = now
            print(f"wmdist: eval: {len(returns)}/{episodes} episodes, mean return {np.mean(returns):.2f}",
                  file=err, flush=True)
    return report


def evaluate_run(run_dir: str, episodes: int = 10, video: str | None = None, human: bool = False,
                 out: IO[str] | None = None, progress_seconds: float = 10.0, simulations: int = 0,
                 explore: bool = False) -> int:
    """`simulations` > 0: search this many simulations per move (as `eval.num_simulations`); `explore`:
    act as the collectors do (as `eval.explore`, which the run's own config may also set)."""
    out = out or sys.stdout  # looked up per call: a default bound at import outlives a redirected stdout
    check_output_path(video, "--video")
    overrides = [f"eval.num_simulations={simulations}"] if simulations else []
    if explore:
        overrides.append("eval.explore=true")
    cfg, spec, algo, version, weights, ckpt = load_run(run_dir, overrides)
    if cfg.eval.num_simulations:  # the in-training evaluator's search count, not self-play's
        algo = build_algorithm(evaluation_config(cfg), spec, cfg.run.seed + 31_337)
    policy = algo.make_policy("cpu")
    policy.set_weights(weights, version)
    sims = f", {cfg.eval.num_simulations} simulations per move" if cfg.eval.num_simulations else ""
    how = ", actions sampled as in self-play" if cfg.eval.explore else ""
    print(f"wmdist: {ckpt.name} (weights v{version}) on {cfg.env.id}{sims}{how}", file=out)
    if spec.players == 2:
        from wmdist.envs.factory import make_env

        env = make_env(cfg.env, cfg.run.seed)
        opponent = _human(env, out) if human else default_opponent(env, cfg.run.seed, cfg.eval.opponent_rollouts)
        outcomes = play_games(policy, env, episodes, opponent)
        for p, rs in outcomes.items():
            rs = np.asarray(rs)
            print(f"agent as player {p}: {len(rs)} games, won {(rs > 0).sum()}, drew {(rs == 0).sum()}, "
                  f"lost {(rs < 0).sum()}", file=out)
        if env.game.name == "tictactoe" and not human:
            _print_lines(judge_lines(policy, env), out)
        return 0
    from wmdist.envs.vector import make_vector_env
    from wmdist.runtime.roles.evaluator import play_episodes

    venv = make_vector_env(cfg.env, min(episodes, cfg.eval.envs), cfg.run.seed + 5)
    returns, lengths = play_episodes(policy, venv, episodes, cfg.eval.explore,
                                     on_episode=episode_progress(episodes, progress_seconds, sys.stderr))
    print("returns: " + " ".join(f"{r:.1f}" for r in returns), file=out)
    print(f"mean return {np.mean(returns):.2f} +- {np.std(returns):.2f} over {len(returns)} episodes "
          f"(mean length {np.mean(lengths):.0f})", file=out)
    if video:
        print(f"video: {record_video(cfg, algo, weights, version, video)}", file=out)
        _to_tensorboard(run_dir, cfg, "eval_video", video)
    return 0


def _to_tensorboard(run_dir: str, cfg, tag: str, gif_path: str) -> None:
    """A video the run's commands wrote, also as an image sequence in the run's TensorBoard files."""
    if not cfg.metrics.tensorboard:
        return
    import imageio.v2 as imageio

    from wmdist.telemetry.tensorboard import TensorBoardLog

    tb = TensorBoardLog(run_dir)
    try:
        tb.frames(tag, np.stack([np.asarray(f)[..., :3] for f in imageio.mimread(gif_path)]))
    finally:
        tb.close()


def _print_lines(lines: dict, out: IO[str]) -> None:
    """The whole-tree judgement: every opponent reply at every turn against the greedy agent."""
    for p in (0, 1):
        print(f"every line, agent as player {p}: {lines[f'won_lines_p{p}']} won, {lines[f'drawn_lines_p{p}']} drawn, "
              f"{lines[f'lost_lines_p{p}']} lost", file=out)
    for moves in lines["losing_lines"]:
        print(f"  a losing line (moves, squares 0-8): {' '.join(str(m) for m in moves)}", file=out)


def record_video(cfg, algo, weights, version: int, path: str, max_steps: int = 1000) -> str:
    """One greedy episode rendered to a GIF."""
    import imageio.v2 as imageio

    from wmdist.envs.factory import make_env

    env = make_env(cfg.env, cfg.run.seed + 11)
    policy = algo.make_policy("cpu")
    policy.set_weights(weights, version)
    obs, frames, first = env.reset(), [], True
    legal = env.legal_actions()
    for _ in range(max_steps):
        frames.append(env.render())
        action = greedy_action(policy, obs, legal, env.to_play() if env.spec.players == 2 else None, first)
        first = False
        obs, _, terminated, truncated = env.step(action)
        legal = env.legal_actions()
        if terminated or truncated:
            break
    imageio.mimsave(path, frames, duration=1 / 30)
    return path


def dream_run(run_dir: str, out: str | None = None, horizon: int = 45, stream: IO[str] | None = None) -> int:
    stream = stream or sys.stdout
    check_output_path(out, "--out")
    cfg, spec, algo, version, weights, ckpt = load_run(run_dir)
    from wmdist.envs.factory import make_env

    if not algo.offers(PREDICTS_OBSERVATIONS):
        if algo.offers(PLOTS_EMBEDDINGS):  # no decoder: the planned embedding trajectory against the real one
            path = out or str(Path(run_dir) / "dream.png")
            try:
                plot = algo.embedding_plot(weights, make_env(cfg.env, cfg.run.seed + 17), path, steps=horizon)
            except ValueError as err:  # e.g. planning with untrained weights: one line
                raise ConfigError(f"dream: {err}") from None
            print(f"wmdist: embedding plot {plot}", file=stream)
            return 0
        raise ConfigError(f"dream needs an algorithm that predicts observations or embeddings; {run_dir} trained "
                          f"{cfg.algo_name!r}")

    path = out or str(Path(run_dir) / "dream.gif")
    env = make_env(cfg.env, cfg.run.seed + 17)
    try:
        video = algo.dream_video(weights, env, path, context=5, horizon=horizon)
    except ImportError as err:
        raise ConfigError(f"dream cannot write the video: {err}") from None
    _to_tensorboard(run_dir, cfg, "dream", video)
    print(f"wmdist: dream video {video}", file=stream)
    return 0


def dream_check_run(run_dir: str, rollouts: int = 64, episodes: int = 5, stream: IO[str] | None = None) -> int:
    """`wmdist dream RUN --check`: World Models' dream against the real env, per policy
    (wmdist/algos/worldmodels/dream_check.py); the rows also go to RUN_DIR/dream_check.json."""
    stream = stream or sys.stdout
    cfg, spec, algo, version, weights, ckpt = load_run(run_dir)
    if not algo.offers(CHECKS_DREAM):
        raise ConfigError(f"dream --check scores a policy trained in the model's dream (World Models); {run_dir} "
                          f"trained {cfg.algo_name!r}")
    try:
        state = ck.load_learner_state(ckpt)["learner"]
    except Exception as err:  # noqa: BLE001 - a damaged file: one line
        raise ConfigError(ck.unreadable_message(ckpt, err)) from None
    try:
        rows = algo.dream_check(cfg, weights, state, rollouts, episodes)
    except ValueError as err:
        raise ConfigError(f"dream --check: {err}") from None
    tau = getattr(cfg.algo, "temperature", None)  # the dream's sampling temperature, where the algorithm has one
    for line in format_check(rows, tau, rollouts, episodes):
        print(line, file=stream)
    out = Path(run_dir) / "dream_check.json"
    out.write_text(json.dumps({"checkpoint": ckpt.name, "version": version, "temperature": tau,
                               "rollouts": rollouts, "episodes": episodes, "rows": rows}, indent=1) + "\n")
    print(f"wmdist: dream check {out}", file=stream)
    return 0


def format_check(rows: list[dict], tau: float | None, rollouts: int, episodes: int) -> list[str]:
    """`wmdist dream --check`'s table: each policy's dream score beside its real one."""
    at = f"tau {tau:g}, " if tau is not None else ""
    lines = [f"dream check: {at}{rollouts} dream rollouts and {episodes} real episodes per policy "
             f"(dream: steps survived; real: return)",
             f"{'policy':<18}{'dream':>9}{'real':>9}{'dream/real':>12}"]
    for r in rows:
        ratio = f"{r['dream'] / r['real']:.2f}" if r["real"] else "-"
        lines.append(f"{r['policy']:<18}{r['dream']:>9.1f}{r['real']:>9.1f}{ratio:>12}")
    return lines
