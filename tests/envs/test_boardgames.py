import numpy as np
import pytest

from wmdist.envs import EnvConfig, make_env
from wmdist.envs.boardgames import (
    CONNECT4, TICTACTOE, IllegalMove, SolverOpponent, State, action_values, best_actions, solve,
)

from envs_helpers import assert_obs_matches_spec


def play(game, moves):
    s = game.initial()
    for a in moves:
        s = game.apply(s, a)
    return s


def test_tictactoe_env_turns_rewards_and_observation():
    with make_env(EnvConfig(id="board:tictactoe"), seed=0) as env:
        assert env.spec.players == 2 and env.spec.num_actions == 9 and env.spec.obs_shape == (27,)
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        assert env.to_play() == 0 and env.legal_actions().all()
        obs, r, term, _ = env.step(4)  # player 0 takes the centre
        assert (r, term, env.to_play()) == (0.0, False, 1)
        # player 1's view: own plane empty, opponent plane has the centre, ones plane full
        assert obs[:9].sum() == 0 and obs[9 + 4] == 1 and obs[18:].sum() == 9
        assert not env.legal_actions()[4] and env.legal_actions().sum() == 8
        for a in (0, 3, 1, 5):  # player 0 completes the middle row 3-4-5 with its third move
            obs, r, term, trunc = env.step(a)
        assert (r, term, trunc) == (1.0, True, False)  # reward for the player who just moved
        assert env.state.winner == 0 and not env.legal_actions().any()
        assert env.render().shape == (48, 48, 3)


def test_illegal_moves_are_rejected_clearly_and_leave_state_unchanged():
    with make_env(EnvConfig(id="board:tictactoe"), seed=0) as env:
        env.reset()
        env.step(4)
        before = env.state
        with pytest.raises(IllegalMove, match="illegal move 4: cell occupied"):
            env.step(4)
        with pytest.raises(IllegalMove, match=r"illegal move 9: out of range \[0, 9\)"):
            env.step(9)
        with pytest.raises(ValueError, match="illegal move 1.5"):
            env.step(1.5)
        assert env.state == before and env.to_play() == 1
    s = play(TICTACTOE, [0, 3, 1, 4, 2])  # player 0 wins on the top row
    with pytest.raises(IllegalMove, match="game is over"):
        TICTACTOE.apply(s, 8)
    s = play(CONNECT4, [2] * 6)
    with pytest.raises(IllegalMove, match="illegal move 2: column full"):
        CONNECT4.apply(s, 2)
    assert CONNECT4.legal(s).tolist() == [True, True, False, True, True, True, True]


def test_connect4_gravity_and_wins():
    s = play(CONNECT4, [3, 3])
    board = np.asarray(s.board).reshape(6, 7)
    assert board[5, 3] == 1 and board[4, 3] == 2  # stones stack from the bottom row
    vertical = play(CONNECT4, [0, 1, 0, 1, 0, 1, 0])
    assert vertical.winner == 0 and CONNECT4.terminal(vertical)
    # player 1 builds the diagonal (5,1) (4,2) (3,3) (2,4)
    diag = play(CONNECT4, [0, 1, 2, 2, 3, 3, 4, 3, 4, 4, 6, 4])
    assert diag.winner == 1 and CONNECT4.reward(diag) == 1.0
    assert play(CONNECT4, [0, 1, 2]).winner == -1


def test_game_is_a_pure_copyable_model():
    s0 = TICTACTOE.initial()
    s1 = TICTACTOE.apply(s0, 0)
    assert s0 == State(board=(0,) * 9, to_play=0) and s1 != s0  # apply never mutates
    assert {s0: "root"}[TICTACTOE.initial()] == "root"  # hashable: a memo / tree key
    assert TICTACTOE.winner(s1) is None and not TICTACTOE.terminal(s1)
    draw = play(TICTACTOE, [0, 1, 2, 4, 3, 5, 7, 6, 8])
    assert TICTACTOE.terminal(draw) and TICTACTOE.winner(draw) is None and TICTACTOE.reward(draw) == 0.0


def test_solver_values_on_known_positions():
    assert solve([0] * 9, 0) == 0  # perfect play draws
    # X (player 0) holds 0 and 1, O holds 3 and 4; X to move wins at 2
    win = [1, 1, 0, 2, 2, 0, 0, 0, 0]
    assert solve(win, 0) == 1 and 2 in best_actions(win, 0)
    # Corner opening answered by an adjacent edge: X has a forced (non-immediate) win.
    assert solve([1, 2, 0, 0, 0, 0, 0, 0, 0], 0) == 1
    # After a corner opening, O's only non-losing reply is the centre.
    assert action_values([1, 0, 0, 0, 0, 0, 0, 0, 0], 1) == {a: (0 if a == 4 else -1) for a in range(1, 9)}
    # X threatens the top row; O's only non-losing move is the block at 2.
    block = [1, 1, 0, 0, 2, 0, 0, 0, 0]
    assert best_actions(block, 1) == [2] and solve(block, 1) == 0
    # X has two threats (2 via the top row, 6 via the left column): O to move loses.
    fork = [1, 1, 0, 1, 2, 0, 0, 0, 2]
    assert solve(fork, 1) == -1
    assert solve(play(TICTACTOE, [4])) == 0  # a State carries its own to_play
    with pytest.raises(ValueError, match="9 cells"):
        solve([0] * 8, 0)
    with pytest.raises(ValueError, match="to_play must be 0 or 1"):
        solve([0] * 9, 2)


def test_solver_opponent_never_loses():
    rng = np.random.default_rng(0)
    for game_i in range(20):
        opp = SolverOpponent(seed=game_i)
        s = TICTACTOE.initial()
        solver_player = game_i % 2
        while not TICTACTOE.terminal(s):
            if s.to_play == solver_player:
                a = opp.act(s)
            else:
                a = int(rng.choice(np.flatnonzero(TICTACTOE.legal(s))))
            s = TICTACTOE.apply(s, a)
        assert s.winner in (-1, solver_player)
    # two perfect players always draw
    a, b, s = SolverOpponent(1), SolverOpponent(2), TICTACTOE.initial()
    while not TICTACTOE.terminal(s):
        s = TICTACTOE.apply(s, (a if s.to_play == 0 else b).act(s))
    assert s.winner == -1
