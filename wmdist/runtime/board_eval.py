"""Evaluation of two-player board-game agents against a fixed opponent.

Greedy self-play says nothing about strength (the same policy plays both sides), so the
evaluator and `wmdist eval` play the agent against an opponent instead: the exact solver
for tic-tac-toe (a random optimal move, so games differ), a pure Monte Carlo tree search
(UCT with random rollouts) for connect four, a uniformly random player otherwise. Outcomes
are from the agent's view (+1 win, 0 draw, -1 loss); against a perfect opponent the best
possible mean is 0 and "never loses" means the minimum is 0.

A solver playing only optimal moves never blunders, so it never tests whether the agent
punishes blunders; `judge_lines` (tic-tac-toe) plays the greedy agent against every
opponent move at every turn and counts the lines it loses.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from wmdist.algos.base import Policy
from wmdist.config.schema import EvalConfig
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
            action = int(greedy_action(policy, env.observe(env.state), env.legal_actions(), mover, first))
            first = False
        else:
            action = opponent(env.state)
        _, reward, terminated, _ = env.step(action)
        if terminated:
            return float(reward if mover == agent_player else -reward) + 0.0  # + 0.0: no -0.0 draws


DEFAULT_ROLLOUTS = EvalConfig().opponent_rollouts  # MCTS opponent: about 20 ms per connect-four move at 200


def default_opponent(env: BoardEnv, seed: int, rollouts: int = DEFAULT_ROLLOUTS) -> Opponent:
    """The exact solver for tic-tac-toe; for connect four a UCT opponent with `rollouts`
    random rollouts per move (`eval.opponent_rollouts`); else a uniformly random legal move."""
    if env.game.name == "tictactoe":
        from wmdist.envs.boardgames.solver import SolverOpponent

        return SolverOpponent(seed=seed).act
    if env.game.name == "connect4":
        from wmdist.envs.boardgames.mcts_opponent import MCTSOpponent

        return MCTSOpponent(env.game, rollouts=rollouts, seed=seed).act
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


def judge_lines(policy: Policy, env: BoardEnv, max_examples: int = 3) -> dict:
    """The greedy agent judged over every opponent line (`boardgames/judge.py`), both sides.

    Each position is asked with `first=True`, so even a recurrent policy is a function of
    the position. Returns {won_lines_p0, drawn_lines_p0, lost_lines_p0, (same for p1),
    lost_lines, lines, losing_lines: [moves, ...] (up to `max_examples` per side)}.
    """
    from wmdist.envs.boardgames.judge import judge

    game = env.game
    if game.name != "tictactoe":
        raise ValueError(f"judge_lines enumerates the whole game tree: tic-tac-toe only, not {game.name}")

    def strategy(states: list) -> np.ndarray:  # positions (agent to move) -> [N] actions
        obs = np.stack([env.observe(s) for s in states])  # [N, *obs_shape]
        legal = np.stack([game.legal(s) for s in states])  # [N, A]
        to_play = np.array([s.to_play for s in states])  # [N]
        actions, _ = policy.act(obs, np.ones(len(states), bool), legal, to_play, False)
        return np.asarray(actions)

    result = judge(game, strategy, max_examples=max_examples)
    lines = [list(line) for side in result.sides.values() for line in side.losing_lines]
    return {**result.as_dict(), "losing_lines": lines}
