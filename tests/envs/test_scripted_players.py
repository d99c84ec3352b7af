"""The scripted connect-four players that calibrate the UCT opponent (wmdist/bench/board_opponent.py):
each takes the one-move tactic it names, and the benchmark prints one JSON line per player."""
from __future__ import annotations

import json

from wmdist.bench.board_opponent import PLAYERS, main, play, scripted
from wmdist.envs.boardgames.game import CONNECT4


def _after(moves: list[int]):
    s = CONNECT4.initial()
    for a in moves:
        s = CONNECT4.apply(s, a)
    return s


def test_win_takes_an_immediate_win_and_block_stops_one() -> None:
    # player 0 has three in column 0 and may win there; player 1 has three in column 6
    win_now = _after([0, 6, 0, 6, 0, 5])  # player 0 to move: column 0 wins
    for seed in range(5):
        assert scripted(CONNECT4, True, False, False, seed)(win_now) == 0
    threat = _after([0, 6, 1, 6, 0, 6])  # player 0 to move, no win of its own; player 1 wins at 6 next
    for seed in range(5):
        assert scripted(CONNECT4, True, True, False, seed)(threat) == 6
    moves = {scripted(CONNECT4, True, False, False, seed)(threat) for seed in range(20)}
    assert len(moves) > 1  # without the block rule it moves at random


def test_play_scores_from_the_players_side() -> None:
    always0 = lambda s: 0 if CONNECT4.legal(s)[0] else int(CONNECT4.legal(s).argmax())  # noqa: E731
    always1 = lambda s: 1 if CONNECT4.legal(s)[1] else int(CONNECT4.legal(s).argmax())  # noqa: E731
    assert play(CONNECT4, always0, always1, player_first=True) == 1.0  # four in column 0 first
    assert play(CONNECT4, always0, always1, player_first=False) == -1.0


def test_the_benchmark_prints_a_line_per_player_and_refuses_bad_counts(capsys) -> None:
    assert main(["--games", "2", "--rollouts", "3"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["player"] for r in lines] == list(PLAYERS)
    for r in lines:
        assert abs(r["won"] + r["drawn"] + r["lost"] - 1.0) < 1e-9 and r["opponent"] == "UCT (3 rollouts per move)"
    assert main(["--games", "0"]) == 2
