"""Fake models for search tests and benches (deterministic, no network).

- `HashModel`: outputs are a hash of the path from the root (latent = path id), so any
  two searches that visit the same path see the same numbers.
- `BanditModel`: one step to an absorbing terminal; the root children's Q are exact.
- `TicTacToeModel`: the real tic-tac-toe rules as a perfect two-player model, plus an
  exact negamax solver (`solve`) to label positions.
"""
from __future__ import annotations

import functools
from typing import Any

import numpy as np

_MOD = 2_147_483_647  # path ids stay below 2^31 so id * 1_000_003 fits in int64


def _hash_uniform(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser of int64 ids -> floats in [0, 1) (elementwise, deterministic)."""
    h = x.astype(np.uint64) + np.uint64(0x9E3779B97F4A7C15)
    h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    h = h ^ (h >> np.uint64(31))
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / 2**53)


class HashModel:
    """recurrent_fn whose outputs depend only on the path id (latent [B, 1] int64).

    With `value_prefix`, latents are a tuple (id [B, 1] int64, steps since reset [B, 1]
    float32) and the `reward` output is a prefix that depends on both, so a wrong reset
    flag changes the numbers.
    """

    def __init__(self, num_actions: int, reward_scale: float = 1.0, value_scale: float = 1.0,
                 logit_scale: float = 2.0, value_prefix: bool = False, torch_latents: bool = False) -> None:
        self.num_actions = num_actions
        self.reward_scale = reward_scale
        self.value_scale = value_scale
        self.logit_scale = logit_scale
        self.value_prefix = value_prefix
        self.torch_latents = torch_latents
        self.calls = 0

    def root(self, batch: int, seed: int) -> tuple[Any, np.ndarray, np.ndarray]:
        """(root latents, root logits [B, A], root values [B]) for B distinct roots."""
        ids = (np.arange(batch, dtype=np.int64) + 1 + seed * 7919)[:, None] % _MOD
        _, value, logits = self._outputs(ids[:, 0])
        latent: Any = ids
        if self.value_prefix:
            latent = (ids, np.zeros((batch, 1), dtype=np.float32))
        return self._wrap(latent), logits, value

    def _wrap(self, latent: Any) -> Any:
        if not self.torch_latents:
            return latent
        import torch

        if isinstance(latent, tuple):
            return tuple(torch.from_numpy(np.ascontiguousarray(x)) for x in latent)
        return torch.from_numpy(np.ascontiguousarray(latent))

    def _outputs(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        reward = (2.0 * _hash_uniform(ids * 3) - 1.0) * self.reward_scale
        value = (2.0 * _hash_uniform(ids * 3 + 1) - 1.0) * self.value_scale
        per_action = ids[:, None] * self.num_actions + np.arange(self.num_actions)[None, :]
        logits = (2.0 * _hash_uniform(per_action * 3 + 2) - 1.0) * self.logit_scale
        return reward, value, logits

    def __call__(self, latents: Any, actions: np.ndarray, reset: np.ndarray | None = None):
        self.calls += 1
        if self.value_prefix:
            ids, since = (np.asarray(x) for x in latents)
            since = np.where(reset[:, None], 0.0, since) + 1.0
        else:
            ids = np.asarray(latents)
        next_ids = (ids * 1_000_003 + np.asarray(actions)[:, None] + 1) % _MOD
        reward, value, logits = self._outputs(next_ids[:, 0])
        if self.value_prefix:
            reward = reward + 0.25 * since[:, 0]
            return reward, value, logits, self._wrap((next_ids, since.astype(np.float32)))
        return reward, value, logits, self._wrap(next_ids)

    def step(self, latent: Any, action: int, reset: bool | None = None):
        """One-root adapter for `reference_search` (latent is a row or tuple of rows)."""
        batched = tuple(np.asarray(x)[None] for x in latent) if isinstance(latent, tuple) else np.asarray(latent)[None]
        reset_arr = None if reset is None else np.array([reset])
        r, v, logits, nxt = self(batched, np.array([action]), reset_arr)
        nxt = tuple(np.asarray(x)[0] for x in nxt) if isinstance(nxt, tuple) else np.asarray(nxt)[0]
        return float(r[0]), float(v[0]), logits[0], nxt


class BanditModel:
    """Root latent 0 -> child with reward q[b, a], value 0, then absorbing (all zeros).

    Every root child's Q equals q[b, a] exactly, whatever the discount.
    """

    def __init__(self, q: np.ndarray) -> None:
        self.q = q  # [B, A]

    def root_latent(self) -> np.ndarray:
        return np.zeros((self.q.shape[0], 1), dtype=np.int64)

    def __call__(self, latents: np.ndarray, actions: np.ndarray):
        at_root = latents[:, 0] == 0
        reward = np.where(at_root, self.q[np.arange(len(actions)), actions], 0.0)
        zeros = np.zeros(len(actions))
        return reward, zeros, np.zeros_like(self.q), np.ones_like(latents)


# --- tic-tac-toe ------------------------------------------------------------------------
LINES = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [0, 3, 6], [1, 4, 7], [2, 5, 8], [0, 4, 8], [2, 4, 6]])


def winner_is_mover(board: np.ndarray) -> np.ndarray:
    """board [B, 9] in the mover's view (+1 own, -1 opponent) -> [B] bool: own line complete."""
    return (board[:, LINES].sum(axis=2) == 3).any(axis=1)


class TicTacToeModel:
    """Perfect model: latent [B, 10] int8 = board in the mover's view + terminal flag.

    reward is the mover's: +1 for completing a line, -1 for playing on an occupied cell
    (only possible below the root, where no mask applies), 0 otherwise; a finished game is
    absorbing with zero reward and value. Non-terminal values are 0 and the prior logits
    are 0 on empty cells and ILLEGAL_LOGIT on occupied ones (the rules, no learned
    knowledge), so every value signal comes from exact terminal outcomes.
    """

    num_actions = 9
    ILLEGAL_LOGIT = -20.0

    @classmethod
    def logits(cls, boards: np.ndarray) -> np.ndarray:
        """[B, 9] prior logits from the rules: uniform over empty cells."""
        return np.where(boards[:, :9] == 0, 0.0, cls.ILLEGAL_LOGIT)

    def __call__(self, latents: np.ndarray, actions: np.ndarray):
        lat = np.asarray(latents)
        batch = len(actions)
        rows = np.arange(batch)
        board = lat[:, :9].astype(np.int64)
        done = lat[:, 9] != 0
        occupied = board[rows, actions] != 0
        after = board.copy()
        after[rows, actions] = np.where(occupied, after[rows, actions], 1)
        won = winner_is_mover(after) & ~occupied
        full = (after != 0).all(axis=1)
        reward = np.where(done, 0.0, np.where(occupied, -1.0, np.where(won, 1.0, 0.0)))
        finished = done | occupied | won | full
        nxt = np.zeros_like(lat)
        nxt[:, :9] = np.where(done[:, None], board, -after)  # next mover's view
        nxt[:, 9] = finished
        return reward, np.zeros(batch), self.logits(nxt), nxt


@functools.lru_cache(maxsize=None)
def solve(board: tuple[int, ...]) -> int:
    """Exact negamax value for the mover (+1 win, 0 draw, -1 loss) of a non-terminal board."""
    best = -2
    for a in range(9):
        if board[a] != 0:
            continue
        after = list(board)
        after[a] = 1
        if winner_is_mover(np.array([after]))[0]:
            return 1
        if all(c != 0 for c in after):
            best = max(best, 0)
            continue
        best = max(best, -solve(tuple(-c for c in after)))
    return best


def move_values(board: tuple[int, ...]) -> dict[int, int]:
    """Exact value of each legal move for the mover."""
    values = {}
    for a in range(9):
        if board[a] != 0:
            continue
        after = list(board)
        after[a] = 1
        if winner_is_mover(np.array([after]))[0]:
            values[a] = 1
        elif all(c != 0 for c in after):
            values[a] = 0
        else:
            values[a] = -solve(tuple(-c for c in after))
    return values
