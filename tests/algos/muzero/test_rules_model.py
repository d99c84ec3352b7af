"""`algo.tree_model: rules`: the search plans with the true rules of a board game, so it
sees wins and losses inside the tree exactly; bad combinations are one config line."""
from pathlib import Path

import numpy as np
import pytest
import torch

from wmdist.algos.muzero.build import build_net
from wmdist.algos.muzero.rules_model import RulesModel, rules_for
from wmdist.algos.muzero.searcher import Searcher
from wmdist.config.errors import ConfigError
from wmdist.config.loader import load_config
from wmdist.envs.boardgames.env import BoardEnv
from wmdist.envs.boardgames.game import CONNECT4
from wmdist.runtime.preflight import check_env_and_algo
from wmdist.search.api import SearchConfig, search

CONFIGS = Path(__file__).parents[3] / "configs"
WIN_AT_3 = [0, 0, 1, 1, 2, 2]  # the first player holds columns 0-2 of the bottom row and moves
BLOCK_AT_3 = [0, 6, 1, 6, 2]  # the second player moves and must block column 3


def _obs(moves, planes):
    env = BoardEnv(CONNECT4, obs="planes" if planes else "vector")
    env.reset()
    for a in moves:
        env.step(np.int64(a))
    return env.observe(env.state)[None], env.legal_actions()[None], np.array([env.to_play()])


def _blind(obs):
    """A network that knows nothing: value 0, uniform prior (isolates the tree and the rules)."""
    return np.zeros(len(obs), np.float32), np.zeros((len(obs), CONNECT4.cols), np.float32)


@pytest.mark.parametrize("moves,planes", [(WIN_AT_3, True), (BLOCK_AT_3, True), (WIN_AT_3, False), (BLOCK_AT_3, False)])
def test_search_over_the_rules_takes_a_win_and_blocks_a_loss_with_a_blind_network(moves, planes):
    obs, legal, to_play = _obs(moves, planes)
    model = RulesModel(rules_for(BoardEnv(CONNECT4, obs="planes" if planes else "vector").spec), _blind)
    value, logits = _blind(obs)
    out = search(model.root(obs), logits, value, legal, to_play, model, SearchConfig(num_simulations=200, discount=1.0),
                 np.random.default_rng(0), temperature=0.0, add_noise=False, two_player=True)
    assert out.action[0] == 3
    if moves is WIN_AT_3:
        assert out.q_values[0, 3] == pytest.approx(1.0)  # the win is exact in the tree
    else:  # every other move lets the opponent win next: its value is a sure loss once seen
        others = [a for a in range(7) if a != 3 and out.visit_counts[0, a] > 1]
        assert others and all(out.q_values[0, a] < -0.4 for a in others)


def test_the_learned_model_with_a_blind_network_does_not_see_the_win():
    """The control: the same search over a learned model that predicts no rewards is indifferent."""
    obs, legal, to_play = _obs(WIN_AT_3, True)

    def learned(latents, actions):  # a model that has not learned the game's rewards
        return (np.zeros(len(actions), np.float32), *_blind(latents), latents.copy())

    value, logits = _blind(obs)
    out = search(obs.copy(), logits, value, legal, to_play, learned, SearchConfig(num_simulations=200, discount=1.0),
                 np.random.default_rng(0), temperature=0.0, add_noise=False, two_player=True)
    assert out.q_values[0, 3] == pytest.approx(0.0)


def test_the_searcher_plans_with_the_rules_and_a_real_network():
    cfg = load_config(CONFIGS / "muzero_connect4.yaml", ["algo.tree_model=rules"])
    _, algo = check_env_and_algo(cfg)
    spec = BoardEnv(CONNECT4, obs="planes").spec
    net = build_net(spec, cfg.algo).eval()
    searcher = Searcher(net, SearchConfig(num_simulations=100, discount=1.0), 1, 1, True, torch.device("cpu"),
                        rules=rules_for(spec))
    obs, legal, to_play = _obs(WIN_AT_3, True)
    res = searcher.run(obs, legal, to_play, np.random.default_rng(0), add_noise=False, temperature=0.0)
    assert res.action[0] == 3 or res.visit_counts[0].argmax() == 3
    assert res.net_seconds > 0
    policy = algo.make_policy()
    assert policy.searcher.rules_model is not None  # the preset's roles get the rules


def _one_line(err):
    msg = str(err.value)
    assert "\n" not in msg
    return msg


def test_rules_on_an_env_without_known_rules_is_a_config_error():
    cfg = load_config(CONFIGS / "muzero_cartpole.yaml", ["algo.tree_model=rules"])
    with pytest.raises(ConfigError) as err:
        check_env_and_algo(cfg)
    assert "tree_model=rules" in _one_line(err) and "CartPole" in _one_line(err)


def test_rules_with_a_value_prefix_is_a_config_error():
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS / "efficientzero_cartpole.yaml", ["algo.tree_model=rules"])
    assert "tree_model=rules" in _one_line(err)
