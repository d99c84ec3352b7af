import numpy as np
import pytest

from wmdist.envs.boardgames import CONNECT4, TICTACTOE
from wmdist.envs.boardgames.game import State
from wmdist.envs.boardgames.mcts_opponent import MCTSOpponent


def play(game, players, first_state=None):
    """Winner (0/1) or None of a game between two state -> action callables."""
    s = first_state or game.initial()
    while not game.terminal(s):
        s = game.apply(s, players[s.to_play](s))
    return game.winner(s)


def random_player(game, seed):
    rng = np.random.default_rng(seed)
    return lambda s: int(rng.choice(np.flatnonzero(game.legal(s))))


def test_connect4_mcts_beats_random_most_games():
    wins = 0
    for g in range(10):
        mcts, rand = MCTSOpponent(CONNECT4, rollouts=40, seed=g), random_player(CONNECT4, 100 + g)
        side = g % 2  # MCTS moves first in even games
        wins += play(CONNECT4, [mcts, rand] if side == 0 else [rand, mcts]) == side
    assert wins >= 8


def test_takes_an_immediate_win_and_blocks_one():
    # Player 0 has three in the bottom row (columns 0-2); column 3 completes it.
    board = [0] * 42
    for c in (0, 1, 2):
        board[35 + c] = 1
    for c in (0, 1, 2):
        board[28 + c] = 2  # player 1's stones on top, no threat of their own
    s = State(board=tuple(board), to_play=0, moves=6)
    assert MCTSOpponent(CONNECT4, rollouts=100, seed=0).act(s) == 3
    # Same bottom row with player 1 to move (one stone fewer for player 1): it must block at 3.
    board[30] = 0
    s = State(board=tuple(board), to_play=1, moves=5)
    assert MCTSOpponent(CONNECT4, rollouts=200, seed=0).act(s) == 3


def test_seeded_same_move_and_bad_rollouts_refused():
    s = TICTACTOE.apply(TICTACTOE.initial(), 4)
    a = [MCTSOpponent(TICTACTOE, rollouts=50, seed=7).act(s) for _ in range(2)]
    assert a[0] == a[1]  # same seed, same move
    with pytest.raises(ValueError, match="rollouts must be >= 1"):
        MCTSOpponent(CONNECT4, rollouts=0)
