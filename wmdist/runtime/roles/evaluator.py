"""Evaluation (greedy unless eval.explore): the evaluator role during training and `wmdist eval` afterwards."""
from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from wmdist.algos.base import Policy
from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.roles.setup import build_algorithm, device_for, evaluation_config, process_tag, set_threads
from wmdist.runtime.roles.weights import pull


def play_episodes(policy: Policy, venv: Any, episodes: int, explore: bool = False,
                  max_steps: int = 1_000_000,
                  on_episode: Callable[[list[float]], None] | None = None) -> tuple[list[float], list[int]]:
    """Run `episodes` episodes over a VectorEnv (greedy unless explore); returns returns and lengths.

    Each env has a fixed quota of episodes (an even split), so short episodes are not
    over-represented the way "first N to finish" would. `on_episode(returns so far)` is
    called as each counted episode ends (progress for long evaluations).
    """
    E = venv.num_envs
    quota = np.array([episodes // E + (i < episodes % E) for i in range(E)])
    done_count = np.zeros(E, np.int64)
    ret = np.zeros(E)
    length = np.zeros(E, np.int64)
    returns: list[float] = []
    lengths: list[int] = []
    step = venv.reset()
    for _ in range(max_steps):
        if (done_count >= quota).all():
            break
        actions, _ = policy.act(step.obs, step.first, step.legal, step.to_play, explore)
        step = venv.step(np.asarray(actions))
        ret += step.reward
        length += 1
        for i in np.flatnonzero(step.terminated | step.truncated):
            if done_count[i] < quota[i]:
                returns.append(float(ret[i]))
                lengths.append(int(length[i]))
                done_count[i] += 1
                if on_episode is not None:
                    on_episode(returns)
            ret[i], length[i] = 0.0, 0
    return returns, lengths


class EvaluatorRole:
    def __init__(self, cfg: RunConfig, spec: EnvSpec, broker: Any, threads: int = 1) -> None:
        from wmdist.envs.vector import make_vector_env

        set_threads(threads)
        self.tag = process_tag()  # who answers (the driver counts restarts by it)
        self.cfg, self.broker = cfg, broker
        seed = cfg.run.seed + 99_991
        self.policy = build_algorithm(evaluation_config(cfg), spec, seed).make_policy(device_for(cfg.eval.gpus))
        self.board = None
        if spec.players == 2:
            # Greedy self-play measures nothing: play an opponent (the exact solver for
            # tic-tac-toe), so the eval return is the mean outcome and its minimum says
            # whether the agent lost a game.
            from wmdist.envs.factory import make_env
            from wmdist.runtime.board_eval import default_opponent

            self.board = make_env(cfg.env, seed)
            self.opponent = default_opponent(self.board, seed, cfg.eval.opponent_rollouts)
        else:
            self.venv = make_vector_env(cfg.env, min(cfg.eval.envs, cfg.eval.episodes), seed)
        self.version = -1
        self.weights = None  # the weights being evaluated (sent back when the judge says stop)

    def evaluate(self) -> dict:
        t0 = time.monotonic()
        version, weights = pull(self.broker, self.version, evaluator=True)
        if weights is not None:
            self.policy.set_weights(weights, version)
            self.version, self.weights = version, weights
        extra: dict = {}
        if self.board is not None:
            from wmdist.runtime.board_eval import play_games

            outcomes = play_games(self.policy, self.board, self.cfg.eval.episodes, self.opponent)
            returns = outcomes[0] + outcomes[1]
            lengths = [0] * len(returns)
            # Fractions of games won and lost: the mean outcome alone hides draws (connect four's target is games won)
            extra = {"eval_won": float(np.mean(np.asarray(returns) > 0)),
                     "eval_lost": float(np.mean(np.asarray(returns) < 0)), **self._judge()}
        else:
            returns, lengths = play_episodes(self.policy, self.venv, self.cfg.eval.episodes, self.cfg.eval.explore)
        return {"version": self.version, "returns": returns, "lengths": lengths,
                "busy_seconds": time.monotonic() - t0, **extra, **self.tag}

    def _judge(self) -> dict:
        """Games small enough to enumerate (tic-tac-toe) are also judged over every opponent line:
        an opponent that only plays optimal moves never reaches the positions a blunder opens.
        Reported as eval_lost_lines / eval_lines (metrics.jsonl, TensorBoard)."""
        if self.board.game.name != "tictactoe":
            return {}
        from wmdist.runtime.board_eval import judge_lines

        lines = judge_lines(self.policy, self.board)
        out = {"eval_lost_lines": int(lines["lost_lines"]), "eval_lines": int(lines["lines"])}
        stop_at = self.cfg.run.stop_at_lost_lines
        if stop_at is not None and out["eval_lost_lines"] <= stop_at:
            # the learner has moved on since these weights: the run keeps the ones that were judged
            out["judged_weights"] = self.weights
        return out

    def ping(self) -> bool:
        return True
