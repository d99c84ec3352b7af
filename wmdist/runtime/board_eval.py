"""Evaluation of two-player board-game agents against a fixed opponent.

Greedy self-play says nothing about strength (the same policy plays both sides), so the
evaluator and `wmdist eval` play the agent against an opponent instead: the exact solver
for tic-tac-toe (a random optimal move, so games differ), a uniformly random player
otherwise. Outcomes are from the agent's view (+1 win, 0 draw, -1 loss); against a perfect
opponent the best possible mean is 0 and "never loses" means the minimum is 0.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from wmdist.algos.base import Policy
from wmdist.envs.boardgames.env import BoardEnv

Opponent = Callable[[object], int]  # state -> action


def greedy_action(policy: Policy, obs: np.ndarray, legal: np.ndarray | None, to_play: int | None, first: bool):
    """The policy's greedy action for one observation (legal and to_play optional)."""
    actions, _ = policy.act(obs[None], np.array([first]), None if legal is None else legal[None],
                            None if to_play is None else np.array([to_play]), False)
    return np.asarray(actions)[0]


def play_board(policy: Policy, env: BoardEnv, agent_player: int, opponent: Opponent) -> float:
    """One game; returns +1 / 0 / -1 from the agent's point of view."""
    env.reset()
    first = True
    while True:
        mover = env.to_play()
        if mover == agent_player:
            action = int(greedy_action(policy, env.game.observe(env.state), env.legal_actions(), mover, first))
            first = False
        else:
            action = opponent(env.state)
        _, reward, terminated, _ = env.step(action)
        if terminated:
            return float(reward if mover == agent_player else -reward) + 0.0  # + 0.0: no -0.0 draws


def default_opponent(env: BoardEnv, seed: int) -> Opponent:
    """The exact solver where one exists (tic-tac-toe), else a uniformly random legal move."""
    if env.game.name == "tictactoe":
        from wmdist.envs.boardgames.solver import SolverOpponent

        return SolverOpponent(seed=seed).act
    rng = np.random.default_rng(seed)
    return lambda _state: int(rng.choice(np.flatnonzero(env.legal_actions())))


def play_games(policy: Policy, env: BoardEnv, games: int, opponent: Opponent) -> dict[int, list[float]]:
    """`games` games alternating sides (even games: agent moves first); outcomes per agent side."""
    outcomes: dict[int, list[float]] = {0: [], 1: []}
    for g in range(games):
        outcomes[g % 2].append(play_board(policy, env, g % 2, opponent))
    return outcomes


def summary(outcomes: dict[int, list[float]]) -> dict[str, int]:
    """Counts {won_p0, drew_p0, lost_p0, won_p1, ...} by the agent's side."""
    out: dict[str, int] = {}
    for side, rs in outcomes.items():
        r = np.asarray(rs)
        out.update({f"won_p{side}": int((r > 0).sum()), f"drew_p{side}": int((r == 0).sum()),
                    f"lost_p{side}": int((r < 0).sum())})
    return out
