"""`eval.explore` / `wmdist eval --explore`: evaluation acts as the collectors do (DreamerV3's own
evaluation samples its actor) instead of greedily; board games refuse it in one line."""
from __future__ import annotations

import io

import pytest

from tests.runtime.run_dirs import run_dir_with_checkpoint
from wmdist.config.errors import ConfigError
from wmdist.config.loader import load_config
from wmdist.runtime.calls import LocalHandle, Ready
from wmdist.runtime.evaluate import load_run
from wmdist.runtime.roles.evaluator import EvaluatorRole
from wmdist.runtime.roles.weights import WeightBroker

SMALL = ["eval.episodes=2", "eval.envs=2", "algo.deter=16", "algo.units=16", "algo.stoch=4", "algo.classes=4"]


def _spy(policy) -> list[bool]:
    """Record the `explore` flag of every act call, then act as the real policy does."""
    flags: list[bool] = []
    real = policy.act

    def act(obs, first, legal, to_play, explore):
        flags.append(bool(explore))
        return real(obs, first, legal, to_play, explore)
    policy.act = act
    return flags


@pytest.mark.parametrize("explore", [False, True])
def test_the_evaluator_acts_greedily_unless_eval_explore(tmp_path, explore):
    run = run_dir_with_checkpoint(tmp_path, "dreamerv3_cartpole", [*SMALL, f"eval.explore={str(explore).lower()}"])
    cfg, spec, _algo, version, weights, _ = load_run(str(run))
    broker = WeightBroker()
    broker.publish(version, [Ready(weights)])
    role = EvaluatorRole(cfg, spec, LocalHandle(broker))
    flags = _spy(role.policy)
    res = role.evaluate()
    assert len(res["returns"]) == 2 and flags and set(flags) == {explore}


def test_wmdist_eval_explore_samples_and_says_so(tmp_path, monkeypatch):
    from wmdist.runtime import evaluate as ev
    from wmdist.runtime.roles import evaluator

    run = run_dir_with_checkpoint(tmp_path, "dreamerv3_cartpole", SMALL)
    acted: list[bool] = []
    real = evaluator.play_episodes

    def play(policy, venv, episodes, explore=False, **kw):
        flags = _spy(policy)
        try:
            return real(policy, venv, episodes, explore, **kw)
        finally:
            acted.extend(flags)
    monkeypatch.setattr(evaluator, "play_episodes", play)
    for explore in (False, True):
        acted.clear()
        out = io.StringIO()
        assert ev.evaluate_run(str(run), episodes=2, out=out, explore=explore) == 0
        assert ("actions sampled as in self-play" in out.getvalue()) == explore
        assert acted and set(acted) == {explore}


def test_board_games_refuse_eval_explore_in_one_line(tmp_path, capsys):
    from wmdist.cli import main

    with pytest.raises(ConfigError, match="eval.explore: board games are judged greedily"):
        load_config("configs/muzero_tictactoe.yaml", ["eval.explore=true"])
    run = run_dir_with_checkpoint(tmp_path, "muzero_tictactoe", ["eval.episodes=2", "algo.search.num_simulations=4"])
    assert main(["eval", str(run), "--episodes", "2", "--explore"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["wmdist: error: eval.explore: board games are judged greedily against the opponent (leave it false)"]
