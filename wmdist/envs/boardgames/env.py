"""`board:tictactoe` and `board:connect4` behind the wmdist `Env` interface.

Observation: `Game.observe` -- planes [own stones, opponent stones, ones] from the view
of the player to move. `obs="vector"`: flattened to float32 `(3 * rows * cols,)` (27 for
tic-tac-toe, 126 for connect four; MLP nets). `obs="planes"`: uint8 `(rows, cols, 3)`
channels-last of 0/255, the project's image convention, so a conv net sees the board as a
grid and a 3x3 filter can find a line anywhere (`env.board_obs`). `to_play()` alternates 0, 1, ...; the reward returned by `step`
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

    def __init__(self, game: Game | str, seed: int = 0, obs: str = "vector") -> None:
        self.game = GAMES[game] if isinstance(game, str) else game
        if obs not in ("vector", "planes"):
            raise ValueError(f"board observation must be 'vector' or 'planes', got {obs!r}")
        self.planes = obs == "planes"
        self.state: State = self.game.initial()
        g = self.game
        self.spec = EnvSpec(
            id=f"board:{g.name}", obs_shape=(g.rows, g.cols, 3) if self.planes else (g.obs_dim,),
            obs_dtype="uint8" if self.planes else "float32", obs_kind="image" if self.planes else "vector",
            num_actions=g.num_actions, players=2, max_episode_steps=g.num_cells, symmetries=self._obs_symmetries(),
        )

    def _obs_symmetries(self) -> tuple:
        """Game symmetries lifted to the flattened observation: each of the 3 planes permuted
        alike (vector: plane-major, index p * cells + c; planes: cell-major, index c * 3 + p)."""
        n = self.game.num_cells
        out = []
        for cell_perm, action_perm in self.game.symmetries():
            if self.planes:
                obs_perm = tuple(c * 3 + p for c in cell_perm for p in range(3))
            else:
                obs_perm = tuple(p * n + c for p in range(3) for c in cell_perm)
            out.append((obs_perm, action_perm))
        return tuple(out)

    def observe(self, state: State) -> np.ndarray:
        """`state` as this env's observation (vector or planes; see the module docstring)."""
        flat = self.game.observe(state)  # [3 * cells] plane-major, 0/1
        if not self.planes:
            return flat
        g = self.game
        return (flat.reshape(3, g.rows, g.cols).transpose(1, 2, 0) * 255).astype(np.uint8)  # [rows, cols, 3]

    def reset(self, seed: int | None = None) -> np.ndarray:
        self.state = self.game.initial()
        return self.observe(self.state)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool]:
        a = np.asarray(action)
        if a.ndim != 0 or not np.issubdtype(a.dtype, np.integer):
            raise IllegalMove(f"illegal move {action!r}: an action is one int in [0, {self.game.num_actions})")
        self.state = self.game.apply(self.state, a)  # raises IllegalMove before changing anything
        return self.observe(self.state), self.game.reward(self.state), self.game.terminal(self.state), False

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
