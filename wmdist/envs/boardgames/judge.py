"""Judge a deterministic board-game strategy over every line the opponent can choose.

A greedy agent is a function of the position, so its strategy together with the game
fixes a game tree in which only the opponent branches. Enumerating that tree (every
opponent move at every opponent turn) and counting the lines the agent loses says whether
the strategy is unbeatable, which sampled games against an optimal opponent cannot: a
solver that plays only optimal moves never makes the blunders an agent must punish.

Tic-tac-toe has a few hundred such lines per side (at most 8*6*4*2 = 384 when the agent
moves first, 9*7*5*3 = 945 when it moves second); `max_lines` guards larger games.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from wmdist.envs.boardgames.game import Game, State

# The agent's strategy, batched: positions (agent to move) -> one legal action each.
BatchStrategy = Callable[[Sequence[State]], Sequence[int]]


@dataclass
class SideResult:
    """Lines of the game tree with the agent playing one side, by outcome for the agent."""

    won: int = 0
    drawn: int = 0
    lost: int = 0
    losing_lines: list[tuple[int, ...]] = field(default_factory=list)  # example move sequences, both players' moves

    @property
    def lines(self) -> int:
        return self.won + self.drawn + self.lost


@dataclass
class JudgeResult:
    sides: dict[int, SideResult]  # agent's player (0 moves first) -> its lines

    @property
    def lost(self) -> int:
        return sum(s.lost for s in self.sides.values())

    def as_dict(self) -> dict:
        """Flat counts for logging: {won_lines_p0, drawn_lines_p0, lost_lines_p0, ..., lost_lines, lines}."""
        out: dict = {}
        for p, s in self.sides.items():
            out.update({f"won_lines_p{p}": s.won, f"drawn_lines_p{p}": s.drawn, f"lost_lines_p{p}": s.lost})
        out["lost_lines"] = self.lost
        out["lines"] = sum(s.lines for s in self.sides.values())
        return out


def single(strategy: Callable[[State], int]) -> BatchStrategy:
    """A batched strategy from a one-position strategy."""
    return lambda states: [strategy(s) for s in states]


def judge_side(game: Game, strategy: BatchStrategy, agent: int, max_examples: int = 5,
               max_lines: int = 100_000) -> SideResult:
    """Every line of the tree where `agent` (0 or 1) plays `strategy` and the opponent any
    legal move; breadth first, so each ply asks the strategy once for all its positions."""
    if agent not in (0, 1):
        raise ValueError(f"agent must be player 0 or 1, got {agent!r}")
    result = SideResult()
    frontier: list[tuple[State, tuple[int, ...]]] = [(game.initial(), ())]  # (position, moves so far)
    while frontier:
        agent_turn = [item for item in frontier if item[0].to_play == agent]
        unique = list(dict.fromkeys(s for s, _ in agent_turn))  # transpositions: ask once per position
        chosen = dict(zip(unique, (int(a) for a in strategy(unique)))) if unique else {}
        nxt: list[tuple[State, tuple[int, ...]]] = []
        for state, line in frontier:
            legal = np.flatnonzero(game.legal(state))
            if state.to_play == agent:
                a = chosen[state]
                if a not in legal:
                    raise ValueError(f"strategy played illegal move {a} after moves {list(line)}")
                moves = [a]
            else:
                moves = [int(m) for m in legal]
            for m in moves:
                child = game.apply(state, m)
                if game.terminal(child):
                    _record(result, game.winner(child), agent, line + (m,), max_examples)
                else:
                    nxt.append((child, line + (m,)))
        if result.lines + len(nxt) > max_lines:
            raise ValueError(f"{game.name}: more than {max_lines} lines; the exhaustive judge is for small games")
        frontier = nxt
    return result


def judge(game: Game, strategy: BatchStrategy, max_examples: int = 5, max_lines: int = 100_000) -> JudgeResult:
    """The strategy judged as the first player and as the second."""
    return JudgeResult({p: judge_side(game, strategy, p, max_examples, max_lines) for p in (0, 1)})


def _record(result: SideResult, winner: int | None, agent: int, line: tuple[int, ...], max_examples: int) -> None:
    if winner is None:
        result.drawn += 1
    elif winner == agent:
        result.won += 1
    else:
        result.lost += 1
        if len(result.losing_lines) < max_examples:
            result.losing_lines.append(line)
