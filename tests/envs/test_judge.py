"""The exhaustive judge: every opponent line against a fixed strategy."""
import numpy as np
import pytest

from wmdist.envs.boardgames import CONNECT4, TICTACTOE, best_actions
from wmdist.envs.boardgames.judge import judge, judge_side, single


def solver_strategy(state):
    return best_actions(state)[0]  # deterministic: the lowest optimal move


def winning_moves(state):
    return [a for a in np.flatnonzero(TICTACTOE.legal(state)) if TICTACTOE.apply(state, a).winner >= 0]


def misses_wins(state):
    """The solver, except that it never takes an immediate win (the planted weakness)."""
    wins = winning_moves(state)
    if not wins:
        return solver_strategy(state)
    return int(next((a for a in np.flatnonzero(TICTACTOE.legal(state)) if a not in wins), wins[0]))


def lowest_cell(state):
    return int(np.flatnonzero(TICTACTOE.legal(state))[0])


def replay(line):
    s = TICTACTOE.initial()
    states = [s]
    for a in line:
        s = TICTACTOE.apply(s, a)
        states.append(s)
    return states


def brute_force_counts(state, agent, strategy):
    """(won, drawn, lost) by plain recursion: an independent count of the same tree."""
    if TICTACTOE.terminal(state):
        w = TICTACTOE.winner(state)
        return (0, 1, 0) if w is None else ((1, 0, 0) if w == agent else (0, 0, 1))
    moves = [strategy(state)] if state.to_play == agent else np.flatnonzero(TICTACTOE.legal(state))
    totals = np.zeros(3, int)
    for a in moves:
        totals += brute_force_counts(TICTACTOE.apply(state, int(a)), agent, strategy)
    return tuple(int(x) for x in totals)


def test_exact_solver_loses_no_line():
    result = judge(TICTACTOE, single(solver_strategy))
    assert result.lost == 0
    for p, side in result.sides.items():
        assert side.lost == 0 and side.losing_lines == []
        assert 0 < side.lines <= (384 if p == 0 else 945)  # a few hundred lines per side
        assert side.won > 0  # the opponent's blunders are punished


def test_planted_weak_policy_loses_lines_and_examples_are_real():
    result = judge(TICTACTOE, single(misses_wins), max_examples=3)
    assert result.lost > 0
    for p, side in result.sides.items():
        for line in side.losing_lines:
            states = replay(line)
            assert states[-1].winner == 1 - p  # the line really ends in the agent's loss
            # ... after the agent passed up an immediate win somewhere on it
            assert any(s.to_play == p and winning_moves(s) for s in states[:-1])
    d = result.as_dict()
    assert d["lost_lines"] == d["lost_lines_p0"] + d["lost_lines_p1"] == result.lost
    assert d["lines"] == sum(s.lines for s in result.sides.values())


@pytest.mark.parametrize("agent", [0, 1])
def test_counts_match_plain_recursion(agent):
    for strategy in (lowest_cell, misses_wins):
        side = judge_side(TICTACTOE, single(strategy), agent)
        assert (side.won, side.drawn, side.lost) == brute_force_counts(TICTACTOE.initial(), agent, strategy)


def test_strategy_asked_once_per_position_and_illegal_move_refused():
    asked = []

    def batched(states):
        asked.extend(states)
        return [lowest_cell(s) for s in states]

    judge_side(TICTACTOE, batched, 1)
    assert len(asked) == len(set(asked))  # transpositions are asked once
    with pytest.raises(ValueError, match="illegal move 0"):
        judge_side(TICTACTOE, single(lambda s: 0), 0)


def test_large_games_are_refused():
    with pytest.raises(ValueError, match="more than 1000 lines"):
        judge_side(CONNECT4, single(lambda s: int(np.flatnonzero(CONNECT4.legal(s))[0])), 0, max_lines=1000)
