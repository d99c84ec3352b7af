"""Board-game evaluation against the exact solver: a perfect agent never loses, a random
one does, and outcomes are counted from the agent's side."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wmdist.algos.base import Policy
from wmdist.envs.boardgames.env import BoardEnv
from wmdist.envs.boardgames.game import State
from wmdist.envs.boardgames.solver import best_actions
from wmdist.envs.boardgames.mcts_opponent import MCTSOpponent
from wmdist.runtime.board_eval import default_opponent, judge_lines, play_games, summary


def _board_from_obs(obs: np.ndarray, to_play: int) -> list[int]:
    own, opp = obs[:9] > 0, obs[9:18] > 0  # planes from the view of the player to move
    board = np.zeros(9, np.int64)
    board[own], board[opp] = to_play + 1, 2 - to_play
    return board.tolist()


class SolverPolicy(Policy):
    """Plays the first optimal move of the position it sees (only through obs and to_play)."""

    def set_weights(self, weights, version):  # noqa: D102
        pass

    def act(self, obs, first, legal, to_play, explore):  # noqa: D102
        acts = [best_actions(_board_from_obs(o, int(p)), int(p))[0] for o, p in zip(obs, to_play)]
        return np.array(acts), {}


class MissesWinsPolicy(SolverPolicy):
    """The solver, except that it takes an immediate win only when every move wins."""

    def act(self, obs, first, legal, to_play, explore):  # noqa: D102
        acts = []
        for o, p, m in zip(obs, to_play, legal):
            board = _board_from_obs(o, int(p))
            wins = {a for a in np.flatnonzero(m) if _wins(board, int(a), int(p))}
            others = [a for a in np.flatnonzero(m) if a not in wins]
            acts.append(others[0] if wins and others else best_actions(board, int(p))[0])
        return np.array(acts), {}


def _wins(board: list[int], a: int, player: int) -> bool:
    b = list(board)
    b[a] = player + 1
    lines = [(0, 1, 2), (3, 4, 5), (6, 7, 8), (0, 3, 6), (1, 4, 7), (2, 5, 8), (0, 4, 8), (2, 4, 6)]
    return any(b[i] == b[j] == b[k] == player + 1 for i, j, k in lines)


class RandomPolicy(SolverPolicy):
    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)

    def act(self, obs, first, legal, to_play, explore):  # noqa: D102
        return np.array([self.rng.choice(np.flatnonzero(m)) for m in legal]), {}


def test_a_perfect_agent_never_loses_to_the_solver() -> None:
    env = BoardEnv("tictactoe")
    outcomes = play_games(SolverPolicy(), env, 40, default_opponent(env, seed=1))
    assert len(outcomes[0]) == len(outcomes[1]) == 20
    s = summary(outcomes)
    assert s["lost_p0"] == s["lost_p1"] == 0
    assert s["won_p0"] == s["won_p1"] == 0  # perfect against perfect: all draws


def test_a_random_agent_loses_and_wins_are_from_its_side() -> None:
    env = BoardEnv("tictactoe")
    outcomes = play_games(RandomPolicy(), env, 40, default_opponent(env, seed=2))
    s = summary(outcomes)
    assert s["won_p0"] == s["won_p1"] == 0  # nobody beats the solver
    assert s["lost_p0"] + s["lost_p1"] >= 20  # a random player loses most games
    assert sum(s.values()) == 40


def test_the_solver_opponent_varies_its_optimal_moves() -> None:
    opp = default_opponent(BoardEnv("tictactoe"), seed=3)
    first_moves = {opp(State(board=(0,) * 9, to_play=0)) for _ in range(50)}
    assert len(first_moves) > 1  # every opening is a draw, so several are optimal
    assert first_moves <= set(range(9))


def test_judge_lines_counts_lost_lines_of_a_weak_agent_only() -> None:
    env = BoardEnv("tictactoe")
    perfect = judge_lines(SolverPolicy(), env)
    assert perfect["lost_lines"] == 0 and perfect["losing_lines"] == []
    assert 0 < perfect["lines"] <= 384 + 945
    weak = judge_lines(MissesWinsPolicy(), env)
    assert weak["lost_lines"] == weak["lost_lines_p0"] + weak["lost_lines_p1"] > 0
    assert 0 < len(weak["losing_lines"]) <= 6  # up to 3 examples per side
    # Every example is a real game the agent lost.
    for line in weak["losing_lines"]:
        env.reset()
        for a in line:
            _, reward, done, _ = env.step(a)
        mover = (len(line) - 1) % 2
        assert done and reward == 1.0 and env.state.winner == mover


def test_connect4_default_opponent_is_mcts_and_beats_a_random_agent() -> None:
    env = BoardEnv("connect4")
    opponent = default_opponent(env, seed=0, rollouts=30)
    assert isinstance(opponent.__self__, MCTSOpponent) and opponent.__self__.rollouts == 30
    s = summary(play_games(RandomPolicy(), env, 6, opponent))
    assert s["lost_p0"] + s["lost_p1"] >= 5


def test_the_evaluator_role_and_wmdist_eval_report_lines_lost(tmp_path):
    """The in-training evaluator reports the whole-tree judgement beside the games (eval_lost_lines,
    eval_lines reach metrics.jsonl), and `wmdist eval` prints it per side."""
    import io

    from tests.runtime.run_dirs import run_dir_with_checkpoint
    from wmdist.runtime.calls import LocalHandle, Ready
    from wmdist.runtime.evaluate import evaluate_run, load_run
    from wmdist.runtime.roles.evaluator import EvaluatorRole
    from wmdist.runtime.roles.weights import WeightBroker

    run = run_dir_with_checkpoint(tmp_path, "muzero_tictactoe", ["eval.episodes=2", "algo.search.num_simulations=4"])
    cfg, spec, _algo, version, weights, _ = load_run(str(run))
    broker = WeightBroker()
    broker.publish(version, [Ready(weights)])  # as the local runner publishes
    res = EvaluatorRole(cfg, spec, LocalHandle(broker)).evaluate()
    assert len(res["returns"]) == 2
    outcomes = np.asarray(res["returns"])
    assert res["eval_won"] == np.mean(outcomes > 0) and res["eval_lost"] == np.mean(outcomes < 0)
    assert res["eval_lines"] > 0 and 0 <= res["eval_lost_lines"] <= res["eval_lines"]
    out = io.StringIO()
    assert evaluate_run(str(run), episodes=2, out=out) == 0
    text = out.getvalue()
    # (an untrained net's search ties break by each policy's own seed: the counts differ between the two)
    sides = [line.split(": ", 1)[1] for line in text.splitlines() if line.startswith("every line")]
    assert len(sides) == 2
    for side in sides:
        won, drawn, lost = (int(part.split()[0]) for part in side.split(", "))
        assert won + drawn + lost > 0


def test_a_run_stops_when_the_judge_finds_no_more_lost_lines_and_keeps_the_judged_weights(tmp_path):
    """`run.stop_at_lost_lines`: the first evaluation whose whole-tree judgement is within the
    bound stops the run (a bound every net meets here), and the final checkpoint holds the
    weights that evaluation judged, not the learner's later ones."""
    import io

    from wmdist.config.loader import load_config
    from wmdist.runtime import checkpoint as ck
    from wmdist.runtime.train import train
    from wmdist.telemetry.curves import read_jsonl

    preset = Path(__file__).parents[2] / "configs" / "muzero_tictactoe.yaml"
    cfg = load_config(str(preset), [f"run.dir={tmp_path}", "ray.local=true", "metrics.enabled=false",
                                    "metrics.tensorboard=false", "checkpoint.every_seconds=0", "run.max_minutes=3",
                                    "eval.every_seconds=0", "eval.every_env_steps=400", "eval.episodes=2",
                                    "replay.min_size=100", "learner.batch_size=8", "algo.search.num_simulations=2",
                                    "algo.hidden=[8]", "algo.latent_dim=8", "run.stop_at_lost_lines=1000"])
    out = io.StringIO()
    assert train(cfg=cfg, out=out) == 0, out.getvalue()
    assert "the judge found" in out.getvalue()
    run_dir = next(p for p in tmp_path.iterdir() if p.is_dir())
    evals = [r for r in read_jsonl(run_dir / "metrics.jsonl") if r.get("kind") == "eval"]
    assert evals and evals[0]["eval_lost_lines"] <= 1000
    version, _ = ck.load_weights(ck.latest_checkpoint(run_dir))
    assert version == evals[0]["eval_version"]


def test_eval_num_simulations_sets_the_evaluators_search_only(tmp_path, capsys):
    """`eval.num_simulations` gives the evaluator (and `wmdist eval --simulations`) its own search count;
    the run's config, which the collectors and learner use, keeps its own. Bad values are one line."""
    from tests.runtime.run_dirs import run_dir_with_checkpoint
    from wmdist.cli import main
    from wmdist.config.errors import ConfigError
    from wmdist.config.loader import load_config
    from wmdist.runtime.calls import LocalHandle
    from wmdist.runtime.evaluate import load_run
    from wmdist.runtime.roles.evaluator import EvaluatorRole
    from wmdist.runtime.roles.setup import evaluation_config
    from wmdist.runtime.roles.weights import WeightBroker

    run = run_dir_with_checkpoint(tmp_path, "muzero_tictactoe", ["eval.episodes=2", "algo.search.num_simulations=4",
                                                                 "eval.num_simulations=9"])
    cfg, spec, *_ = load_run(str(run))
    assert evaluation_config(cfg).algo.search.num_simulations == 9
    assert cfg.algo.search.num_simulations == 4  # a copy: self-play keeps its count
    role = EvaluatorRole(cfg, spec, LocalHandle(WeightBroker()))
    assert role.policy.searcher.cfg.num_simulations == 9
    assert main(["eval", str(run), "--episodes", "2", "--simulations", "6"]) == 0
    assert "6 simulations per move" in capsys.readouterr().out
    with pytest.raises(SystemExit) as bad:  # not a positive int: argparse's one line, exit 2
        main(["eval", str(run), "--episodes", "2", "--simulations", "0"])
    assert bad.value.code == 2
    dreamer = Path(__file__).parents[2] / "configs" / "dreamerv3_cartpole.yaml"
    with pytest.raises(ConfigError, match="eval.num_simulations: algorithm 'dreamer' has no tree search"):
        load_config(str(dreamer), ["eval.num_simulations=8"])
