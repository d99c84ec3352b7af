"""The search's model when the rules are known (`algo.tree_model: rules`): AlphaZero's
perfect simulator in place of MuZero's dynamics network.

Each tree node holds the true position (the env's observation from the mover's view) and
whether its line has ended; the network only evaluates positions, exactly as it sees real
ones (`initial_inference`). Wins and losses inside the tree are therefore exact, which a
learned model of a board game gets wrong until it has seen many endings.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wmdist.envs.boardgames.game import GAMES
from wmdist.envs.boardgames.rules_batch import BatchRules
from wmdist.envs.spec import EnvSpec

MASKED_LOGIT = -1e4  # prior ~0 for an illegal move at an interior node (finite: the softmax stays defined)

# obs [B, *obs_shape] -> (value [B] from the mover's view, policy logits [B, A])
Evaluate = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def rules_for(spec: EnvSpec) -> BatchRules:
    """The batched rules of a `board:<game>` env; ValueError (one line) for any other env."""
    name = spec.id.split(":", 1)[1] if spec.id.startswith("board:") else None
    if name not in GAMES:
        raise ValueError(f"algo.tree_model=rules needs a board game with known rules (board:tictactoe, "
                         f"board:connect4); {spec.id} has none")
    return BatchRules(GAMES[name], planes=len(spec.obs_shape) == 3)


class RulesModel:
    """`recurrent_fn` for `wmdist.search.search` over true positions; latents are
    (obs [B, *obs_shape], done [B] bool)."""

    def __init__(self, rules: BatchRules, evaluate: Evaluate) -> None:
        self.rules, self.evaluate = rules, evaluate

    def root(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The root latents: a private copy of the observations, no line ended."""
        return np.ascontiguousarray(obs).copy(), np.zeros(len(obs), bool)

    def __call__(self, latents: tuple[np.ndarray, np.ndarray], actions: np.ndarray):
        obs, done = latents
        st = self.rules.step(obs, done, actions)
        value, logits = self.evaluate(st.obs)
        value = np.where(st.done, 0.0, value).astype(np.float32)  # an ended line has no future
        logits = np.where(st.legal, logits, MASKED_LOGIT).astype(np.float32)
        return st.reward, value, logits, (st.obs, st.done)
