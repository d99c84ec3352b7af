"""`board:tictactoe` and `board:connect4` behind the wmdist `Env` interface.

Observation: `Game.observe` -- planes [own stones, opponent stones, ones] from the view
of the player to move, flattened to float32 `(3 * rows * cols,)` (27 for tic-tac-toe,
126 for connect four). `to_play()` alternates 0, 1, ...; the reward returned by `step`
is for the player who just moved (+1 for the winning move, 0 otherwise, so a draw is 0).
An illegal action raises `IllegalMove` (a ValueError) and leaves the state unchanged.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from wmdist.envs.boardgames.game import GAMES, Game, IllegalMove, State
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec

_CELL = 16  # render: pixels per cell
_COLOURS = np.array([[225, 225, 225], [200, 40, 40], [240, 200, 30]], dtype=np.uint8)  # empty, p0, p1


class BoardEnv(Env):
    """A two-player board game; deterministic, so seeds have no effect."""

    def __init__(self, game: Game | str, seed: int = 0) -> None:
        self.game = GAMES[game] if isinstance(game, str) else game
        self.state: State = self.game.initial()
        self.spec = EnvSpec(
            id=f"board:{self.game.name}", obs_shape=(self.game.obs_dim,), obs_dtype="float32",
            obs_kind="vector", num_actions=self.game.num_actions, players=2,
            max_episode_steps=self.game.num_cells, symmetries=self._obs_symmetries(),
        )

    def _obs_symmetries(self) -> tuple:
        """Game symmetries lifted to the observation: each of the 3 planes permuted alike."""
        n = self.game.num_cells
        out = []
        for cell_perm, action_perm in self.game.symmetries():
            obs_perm = tuple(p * n + c for p in range(3) for c in cell_perm)
            out.append((obs_perm, action_perm))
        return tuple(out)

    def reset(self, seed: int | None = None) -> np.ndarray:
        self.state = self.game.initial()
        return self.game.observe(self.state)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = np.asarray(action)
        if a.ndim != 0 or not np.issubdtype(a.dtype, np.integer):
            raise IllegalMove(f"illegal move {action!r}: an action is one int in [0, {self.game.num_actions})")
        self.state = self.game.apply(self.state, a)  # raises IllegalMove before changing anything
        return self.game.observe(self.state), self.game.reward(self.state), self.game.terminal(self.state), False

    def legal_actions(self) -> np.ndarray:
        return self.game.legal(self.state)

    def to_play(self) -> int:
        return self.state.to_play

    def render(self) -> np.ndarray:
        g = self.game
        cells = np.asarray(self.state.board).reshape(g.rows, g.cols)
        img = _COLOURS[cells].repeat(_CELL, axis=0).repeat(_CELL, axis=1)  # [R*16, C*16, 3]
        img[::_CELL, :] = 60  # grid lines
        img[:, ::_CELL] = 60
        return np.ascontiguousarray(img)
