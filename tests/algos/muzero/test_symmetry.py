"""Board symmetries: every declared symmetry maps games to equivalent games, and the
learner's augmentation moves observation cells, actions and policy targets together."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.algos.muzero.symmetry import Symmetries
from wmdist.envs.boardgames.env import BoardEnv
from wmdist.envs.boardgames.game import CONNECT4, TICTACTOE


@pytest.mark.parametrize("game,count", [(TICTACTOE, 8), (CONNECT4, 2)])
def test_symmetries_map_games_to_equivalent_games(game, count) -> None:
    syms = game.symmetries()
    assert len(syms) == count
    assert syms[0][0] == tuple(range(game.num_cells)) and syms[0][1] == tuple(range(game.num_actions))
    assert len({s for s in syms}) == count  # all distinct
    rng = np.random.default_rng(0)
    for _ in range(30):
        for cell_perm, action_perm in syms:
            s, t = game.initial(), game.initial()
            while not game.terminal(s):
                a = int(rng.choice(np.flatnonzero(game.legal(s))))
                assert game.legal(t)[action_perm[a]]
                s, t = game.apply(s, a), game.apply(t, action_perm[a])
                moved = np.empty(game.num_cells, np.int64)
                moved[list(cell_perm)] = s.board
                assert tuple(moved) == t.board  # board'[perm[c]] = board[c]
            assert game.terminal(t) and s.winner == t.winner


def test_augmentation_transforms_obs_actions_and_policy_consistently() -> None:
    env = BoardEnv("tictactoe")
    sym = Symmetries(env.spec.symmetries)
    rng = np.random.default_rng(1)
    b, k, a = 16, 3, 9
    # positions reached by random play, and the actions that followed them
    obs, actions = np.zeros((b, 27), np.float32), np.zeros((b, k), np.int64)
    states = []
    for i in range(b):
        s = TICTACTOE.initial()
        for _ in range(rng.integers(0, 3)):
            s = TICTACTOE.apply(s, int(rng.choice(np.flatnonzero(TICTACTOE.legal(s)))))
        states.append(s)
        obs[i] = TICTACTOE.observe(s)
        actions[i] = rng.choice(np.flatnonzero(TICTACTOE.legal(s)), k, replace=False)
    policy = rng.dirichlet(np.ones(a), (b, k + 1)).astype(np.float32)
    g = rng.integers(0, sym.size, b)
    obs_t, actions_t, policy_t = sym.apply(g, obs, actions, policy)
    for i in range(b):
        cell_perm, action_perm = TICTACTOE.symmetries()[g[i]]
        board = np.empty(9, np.int64)
        board[list(cell_perm)] = states[i].board
        # the transformed observation is the observation of the transformed board
        from wmdist.envs.boardgames.game import State
        expect = TICTACTOE.observe(State(board=tuple(board), to_play=states[i].to_play, moves=states[i].moves))
        np.testing.assert_array_equal(obs_t[i], expect)
        np.testing.assert_array_equal(actions_t[i], np.asarray(action_perm)[actions[i]])
        for j in range(k + 1):
            for act in range(a):
                assert policy_t[i, j, action_perm[act]] == policy[i, j, act]
    assert not np.array_equal(obs_t, obs) or (g == 0).all()


def test_augmentation_refuses_envs_without_symmetries() -> None:
    with pytest.raises(ValueError, match="no symmetries"):
        Symmetries(())
