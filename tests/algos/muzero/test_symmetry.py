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


@pytest.mark.parametrize("game", ["tictactoe", "connect4"])
def test_planes_observation_and_its_symmetries_match_the_vector_ones(game) -> None:
    """`env.board_obs: planes` is the same position as the flat vector, laid out (rows, cols, 3)
    0/255; augmenting planes moves the same cells as augmenting the vector."""
    vec, img = BoardEnv(game), BoardEnv(game, obs="planes")
    g = vec.game
    assert img.spec.obs_shape == (g.rows, g.cols, 3) and img.spec.obs_kind == "image"
    rng = np.random.default_rng(2)
    obs_v, obs_p, states = [], [], []
    for _ in range(12):
        s = g.initial()
        for _ in range(rng.integers(0, 6)):
            s = g.apply(s, int(rng.choice(np.flatnonzero(g.legal(s)))))
        states.append(s)
        obs_v.append(vec.observe(s))
        obs_p.append(img.observe(s))
    obs_v, obs_p = np.stack(obs_v), np.stack(obs_p)  # [B, 3*cells], [B, rows, cols, 3]
    assert obs_p.dtype == np.uint8 and set(np.unique(obs_p)) <= {0, 255}
    # plane p, cell (r, c) of the vector is obs_p[:, r, c, p] / 255
    np.testing.assert_array_equal(obs_v.reshape(-1, 3, g.rows, g.cols).transpose(0, 2, 3, 1), obs_p / 255)
    # the stone a player just dropped is in its plane at its cell
    board = np.asarray(states[-1].board).reshape(g.rows, g.cols)
    own = obs_p[-1, :, :, 0] > 0
    np.testing.assert_array_equal(own, board == states[-1].to_play + 1)
    sym_v, sym_p = Symmetries(vec.spec.symmetries), Symmetries(img.spec.symmetries)
    b, k = len(states), 2
    actions = rng.integers(0, g.num_actions, (b, k))
    policy = rng.dirichlet(np.ones(g.num_actions), (b, k + 1)).astype(np.float32)
    choice = np.arange(b) % sym_v.size
    tv, av, pv = sym_v.apply(choice, obs_v, actions, policy)
    tp, ap, pp = sym_p.apply(choice, obs_p, actions, policy)
    assert tp.shape == obs_p.shape
    np.testing.assert_array_equal(tv.reshape(-1, 3, g.rows, g.cols).transpose(0, 2, 3, 1), tp / 255)
    np.testing.assert_array_equal(av, ap)
    np.testing.assert_array_equal(pv, pp)
    assert not np.array_equal(tp, obs_p)  # some rows were reflected


def test_a_wrong_board_observation_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="'vector' or 'planes'"):
        BoardEnv("connect4", obs="pixels")
