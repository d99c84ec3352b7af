"""A board game's true rules on a batch of observations, for a search that plans with them
(AlphaZero's perfect model) instead of a learned dynamics function.

Positions are the env's own observations, from the view of the player to move, so the
network evaluates a searched position exactly as it sees a real one:
- vector: float32 [B, 3 * cells], plane-major [own stones, opponent stones, ones], 0/1;
- planes: uint8 [B, rows, cols, 3], channels-last, 0/255.
`Game.apply` is the reference; `tests/envs/test_rules_batch.py` checks these against it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wmdist.envs.boardgames.game import Game

ILLEGAL_REWARD = -1.0  # an illegal move inside the tree loses for its mover and ends the line


@dataclass
class BatchStep:
    obs: np.ndarray  # [B, *obs_shape] the next position from the view of the next player to move
    done: np.ndarray  # [B] bool: the line has ended (a win, a full board, an illegal move)
    reward: np.ndarray  # [B] float32 for the player who moved: +1 win, 0 otherwise, ILLEGAL_REWARD
    legal: np.ndarray  # [B, A] bool legal actions of the next mover (all False where done)


class BatchRules:
    """Vectorised `Game` rules on observations (numpy; B rows at once)."""

    def __init__(self, game: Game, planes: bool) -> None:
        self.game, self.planes = game, planes

    def boards(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """obs -> (own, opp) bool [B, rows, cols] from the view of the player to move."""
        g = self.game
        if self.planes:
            x = np.asarray(obs) > 127  # [B, rows, cols, 3]
            return x[..., 0], x[..., 1]
        x = np.asarray(obs).reshape(len(obs), 3, g.rows, g.cols) > 0.5
        return x[:, 0], x[:, 1]

    def observe(self, own: np.ndarray, opp: np.ndarray) -> np.ndarray:
        """(own, opp) [B, rows, cols] -> the env's observation of that position."""
        stack = np.stack([own, opp, np.ones_like(own)], axis=-1 if self.planes else 1)
        if self.planes:
            return stack.astype(np.uint8) * np.uint8(255)  # [B, rows, cols, 3]
        return stack.reshape(len(own), -1).astype(np.float32)  # [B, 3 * cells]

    def legal(self, own: np.ndarray, opp: np.ndarray) -> np.ndarray:
        """[B, A] bool: open columns (gravity) or empty cells."""
        empty = ~(own | opp)
        return empty[:, 0, :] if self.game.gravity else empty.reshape(len(own), -1)

    def lines(self, stones: np.ndarray) -> np.ndarray:
        """[B] bool: `stones` [B, rows, cols] hold k in a row in any direction."""
        k, (rows, cols) = self.game.k, stones.shape[1:]
        found = np.zeros(len(stones), bool)
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            r_end, c_lo, c_hi = rows - dr * (k - 1), max(0, -dc * (k - 1)), cols - max(0, dc * (k - 1))
            if r_end <= 0 or c_hi <= c_lo:
                continue
            run = np.ones((len(stones), r_end, c_hi - c_lo), bool)
            for i in range(k):  # the window starting at (r, c) covers (r + i dr, c + i dc)
                run &= stones[:, i * dr:i * dr + r_end, c_lo + i * dc:c_hi + i * dc]
            found |= run.reshape(len(stones), -1).any(-1)
        return found

    def step(self, obs: np.ndarray, done: np.ndarray, actions: np.ndarray) -> BatchStep:
        """The mover plays `actions` [B] in every row; rows already done stay done, reward 0."""
        g = self.game
        own, opp = self.boards(obs)
        own, opp = own.copy(), opp.copy()
        b = np.arange(len(own))
        a = np.asarray(actions, np.int64)
        done = np.asarray(done, bool)
        legal = self.legal(own, opp)[b, a] & ~done
        empty = ~(own | opp)
        if g.gravity:
            col = empty[b, :, a]  # [B, rows] empty cells of the chosen column, top to bottom
            row = g.rows - 1 - np.argmax(col[:, ::-1], axis=1)  # the lowest empty cell
            cell_r, cell_c = row, a
        else:
            cell_r, cell_c = np.divmod(a, g.cols)
        play = b[legal]
        own[play, cell_r[legal], cell_c[legal]] = True
        won = legal & self.lines(own)
        full = legal & (own | opp).reshape(len(own), -1).all(-1) & ~won  # a draw
        reward = np.where(won, 1.0, np.where(legal | done, 0.0, ILLEGAL_REWARD)).astype(np.float32)
        new_done = done | ~legal | won | full
        # the next mover sees the board from its side: its stones are the old opponent's
        nxt_own, nxt_opp = np.where(legal[:, None, None], opp, own), np.where(legal[:, None, None], own, opp)
        out_obs = np.where(legal.reshape((-1,) + (1,) * (np.ndim(obs) - 1)), self.observe(nxt_own, nxt_opp), obs)
        next_legal = self.legal(nxt_own, nxt_opp) & ~new_done[:, None]
        return BatchStep(out_obs.astype(np.asarray(obs).dtype), new_done, reward, next_legal)
