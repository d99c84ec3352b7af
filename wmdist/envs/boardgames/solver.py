"""Exact tic-tac-toe solver (memoised negamax over the ~5.5k reachable positions).

Boards use the `game.py` encoding: 9 cells row-major, 0 empty, 1 player 0, 2 player 1.
Values are for the player to move: +1 forced win, 0 draw, -1 forced loss.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Sequence

import numpy as np

from wmdist.envs.boardgames.game import TICTACTOE, State

_LINES = (
    (0, 1, 2), (3, 4, 5), (6, 7, 8),  # rows
    (0, 3, 6), (1, 4, 7), (2, 5, 8),  # columns
    (0, 4, 8), (2, 4, 6),  # diagonals
)


def _board(board: Sequence[int] | np.ndarray | State) -> tuple[int, ...]:
    if isinstance(board, State):
        board = board.board
    b = tuple(int(x) for x in np.asarray(board).ravel())
    if len(b) != 9 or any(x not in (0, 1, 2) for x in b):
        raise ValueError(f"tic-tac-toe board must be 9 cells in {{0, 1, 2}}, got {list(b)}")
    return b


def _player(board: object, to_play: int | None, fn: str) -> int:
    if to_play is None:
        if not isinstance(board, State):
            raise ValueError(f"{fn}(board, to_play): to_play is required unless board is a State")
        to_play = board.to_play
    if to_play not in (0, 1):
        raise ValueError(f"to_play must be 0 or 1, got {to_play!r}")
    return int(to_play)


def _line_winner(b: tuple[int, ...]) -> int:
    """Player (0/1) owning a full line, or -1."""
    for i, j, k in _LINES:
        if b[i] != 0 and b[i] == b[j] == b[k]:
            return b[i] - 1
    return -1


@lru_cache(maxsize=None)
def _value(b: tuple[int, ...], to_play: int) -> int:
    w = _line_winner(b)
    if w >= 0:
        return 1 if w == to_play else -1
    if 0 not in b:
        return 0
    best = -1
    for a in range(9):
        if b[a] == 0:
            child = b[:a] + (to_play + 1,) + b[a + 1:]
            best = max(best, -_value(child, 1 - to_play))  # negamax: their value is ours negated
            if best == 1:
                break
    return best


def solve(board: Sequence[int] | np.ndarray | State, to_play: int | None = None) -> int:
    """Game-theoretic value in {-1, 0, 1} for `to_play` (defaults to a State's player)."""
    return _value(_board(board), _player(board, to_play, "solve"))


def action_values(board: Sequence[int] | np.ndarray | State, to_play: int | None = None) -> dict[int, int]:
    """{legal action: value for `to_play` after playing it}; empty once the game is over."""
    b, p = _board(board), _player(board, to_play, "action_values")
    if _line_winner(b) >= 0:
        return {}
    return {a: -_value(b[:a] + (p + 1,) + b[a + 1:], 1 - p) for a in range(9) if b[a] == 0}


def best_actions(board: Sequence[int] | np.ndarray | State, to_play: int | None = None) -> list[int]:
    """Every legal action achieving the optimal value for `to_play` (sorted)."""
    values = action_values(board, to_play)
    if not values:
        return []
    top = max(values.values())
    return sorted(a for a, v in values.items() if v == top)


class SolverOpponent:
    """A perfect tic-tac-toe player for evaluation: a random optimal move, or with
    probability `epsilon` a random legal move (a weaker opponent)."""

    def __init__(self, seed: int = 0, epsilon: float = 0.0) -> None:
        if not 0.0 <= epsilon <= 1.0:
            raise ValueError(f"epsilon must be in [0, 1], got {epsilon}")
        self.epsilon = epsilon
        self._rng = np.random.default_rng(seed)

    def act(self, state: State) -> int:
        legal = np.flatnonzero(TICTACTOE.legal(state))
        if legal.size == 0:
            raise ValueError("SolverOpponent.act: the game is over, no legal move")
        if self.epsilon and self._rng.random() < self.epsilon:
            return int(self._rng.choice(legal))
        return int(self._rng.choice(best_actions(state)))
