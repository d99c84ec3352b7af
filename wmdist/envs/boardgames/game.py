"""Rules of k-in-a-row grid games (tic-tac-toe, connect four) as a pure, copyable model.

A `State` is an immutable value (hashable: usable as a memo key or a search-tree node),
so MCTS tests can wrap a `Game` as a perfect model: `apply` returns a new state and
never mutates the old one.

Board encoding: row-major tuple of `rows * cols` cells, row 0 at the top;
0 = empty, 1 = a stone of player 0 (moves first), 2 = a stone of player 1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EMPTY = 0
_DIRECTIONS = ((0, 1), (1, 0), (1, 1), (1, -1))  # horizontal, vertical, two diagonals


class IllegalMove(ValueError):
    """An action that is not legal in the current state (out of range, occupied, game over)."""


@dataclass(frozen=True)
class State:
    board: tuple[int, ...]  # [rows * cols] cells in {0, 1, 2}
    to_play: int  # player to move: 0 or 1
    winner: int = -1  # player who completed a line, or -1
    moves: int = 0  # stones on the board


class Game:
    """A two-player game: place a stone (or drop it, with `gravity`); `k` in a row wins.

    Actions: a cell index `r * cols + c` without gravity, a column index with gravity.
    """

    def __init__(self, name: str, rows: int, cols: int, k: int, gravity: bool) -> None:
        self.name, self.rows, self.cols, self.k, self.gravity = name, rows, cols, k, gravity
        self.num_actions = cols if gravity else rows * cols
        self.num_cells = rows * cols
        self.obs_dim = 3 * self.num_cells

    def symmetries(self) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
        """The board's symmetries as (cell_perm, action_perm) pairs, identity first.

        A symmetry sends cell c to cell_perm[c] and action a to action_perm[a]; the game is
        unchanged by it, so an agent may learn from transformed positions (data
        augmentation). Square boards without gravity: the 8 rotations and reflections;
        otherwise (gravity or non-square): the identity and the left-right mirror.
        """
        grid = np.arange(self.num_cells).reshape(self.rows, self.cols)
        views = [grid, grid[:, ::-1]]
        if self.rows == self.cols and not self.gravity:
            views = [np.rot90(g, k) for g in (grid, grid.T) for k in range(4)]
        out = []
        for v in views:
            cell_perm = np.empty(self.num_cells, np.int64)
            cell_perm[v.ravel()] = np.arange(self.num_cells)  # cell v[i] lands at position i
            if self.gravity:
                action_perm = cell_perm[: self.cols] if v is grid else (self.cols - 1 - np.arange(self.cols))
            else:
                action_perm = cell_perm
            out.append((tuple(int(x) for x in cell_perm), tuple(int(x) for x in action_perm)))
        return tuple(out)

    def initial(self) -> State:
        return State(board=(EMPTY,) * self.num_cells, to_play=0)

    def terminal(self, s: State) -> bool:
        return s.winner >= 0 or s.moves == self.num_cells

    def winner(self, s: State) -> int | None:
        """The winning player, or None (game not over, or a draw)."""
        return s.winner if s.winner >= 0 else None

    def legal(self, s: State) -> np.ndarray:
        """[A] bool: True where the action is legal (all False once the game is over)."""
        if self.terminal(s):
            return np.zeros(self.num_actions, dtype=bool)
        board = np.asarray(s.board).reshape(self.rows, self.cols)
        if self.gravity:
            return board[0] == EMPTY  # a column is open while its top cell is empty
        return board.ravel() == EMPTY

    def apply(self, s: State, action: int) -> State:
        """The state after the player to move plays `action`; raises IllegalMove."""
        a = int(action)
        if self.terminal(s):
            raise IllegalMove(f"illegal move {a}: the {self.name} game is over")
        if not 0 <= a < self.num_actions:
            raise IllegalMove(f"illegal move {a}: out of range [0, {self.num_actions})")
        if self.gravity:
            col = [s.board[r * self.cols + a] for r in range(self.rows)]
            if col[0] != EMPTY:
                raise IllegalMove(f"illegal move {a}: column full")
            row = max(r for r in range(self.rows) if col[r] == EMPTY)  # lowest empty cell
            cell = row * self.cols + a
        else:
            cell = a
            if s.board[cell] != EMPTY:
                raise IllegalMove(f"illegal move {a}: cell occupied")
        board = list(s.board)
        board[cell] = s.to_play + 1
        won = self.completes_line(board, cell)
        return State(
            board=tuple(board), to_play=1 - s.to_play,
            winner=s.to_play if won else -1, moves=s.moves + 1,
        )

    def reward(self, s: State) -> float:
        """Reward for the player who just moved into `s`: +1 if that move won, else 0."""
        return 1.0 if s.winner >= 0 else 0.0

    def observe(self, s: State) -> np.ndarray:
        """[3 * rows * cols] float32: planes [own stones, opponent stones, ones], from the
        view of the player to move, each plane row-major, concatenated."""
        board = np.asarray(s.board)
        own = board == s.to_play + 1
        opp = board == (1 - s.to_play) + 1
        return np.concatenate([own, opp, np.ones_like(own)]).astype(np.float32)

    def completes_line(self, board: list[int], cell: int) -> bool:
        """True if the stone at `cell` is part of `k` in a row."""
        r0, c0 = divmod(cell, self.cols)
        stone = board[cell]
        for dr, dc in _DIRECTIONS:
            count = 1
            for sign in (1, -1):
                r, c = r0 + sign * dr, c0 + sign * dc
                while 0 <= r < self.rows and 0 <= c < self.cols and board[r * self.cols + c] == stone:
                    count += 1
                    r, c = r + sign * dr, c + sign * dc
            if count >= self.k:
                return True
        return False


TICTACTOE = Game("tictactoe", rows=3, cols=3, k=3, gravity=False)
CONNECT4 = Game("connect4", rows=6, cols=7, k=4, gravity=True)
GAMES = {"tictactoe": TICTACTOE, "connect4": CONNECT4}
