"""How strong is the connect-four evaluation opponent? Scripted players against it.

    python -m wmdist.bench.board_opponent --games 40 --rollouts 200

Each scripted player plays `games` games against the UCT opponent (`MCTSOpponent`, the one the
evaluator and `wmdist eval` use), half as first player; one JSON line per player with the share
won, drawn and lost. The players add one-move tactics step by step, so the lines say what an
agent must do beyond them to win most games:

- random: a uniformly random legal move;
- win: takes a move that wins at once, else random;
- win+block: also takes the column where the opponent would win at once;
- win+block+centre: as win+block, but random moves favour the centre columns (weights 1-4).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import random
import sys
from typing import Callable

import numpy as np

from wmdist.envs.boardgames.game import CONNECT4, Game, State
from wmdist.envs.boardgames.mcts_opponent import MCTSOpponent

Player = Callable[[State], int]


def scripted(game: Game, win: bool, block: bool, centre: bool, seed: int) -> Player:
    rng = random.Random(seed)
    centre_col = (game.cols - 1) / 2

    def act(s: State) -> int:
        legal = [int(a) for a in np.flatnonzero(game.legal(s))]
        if win:
            for a in legal:
                if game.winner(game.apply(s, a)) == s.to_play:
                    return a
        if block:
            other = dataclasses.replace(s, to_play=1 - s.to_play)  # the same board, the opponent to move
            for a in legal:
                if game.winner(game.apply(other, a)) == other.to_play:
                    return a
        if centre:
            return rng.choices(legal, weights=[game.cols // 2 + 1 - abs(a - centre_col) for a in legal])[0]
        return rng.choice(legal)
    return act


PLAYERS = {"random": (False, False, False), "win": (True, False, False),
           "win+block": (True, True, False), "win+block+centre": (True, True, True)}


def play(game: Game, player: Player, opponent: Player, player_first: bool) -> float:
    """One game; +1 / 0 / -1 for `player`."""
    s, side = game.initial(), 0 if player_first else 1
    while not game.terminal(s):
        s = game.apply(s, player(s) if s.to_play == side else opponent(s))
    w = game.winner(s)
    return 0.0 if w is None else (1.0 if w == side else -1.0)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--games", type=int, default=40)
    p.add_argument("--rollouts", type=int, default=200, help="the UCT opponent's random rollouts per move")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    if a.games < 1 or a.rollouts < 1:
        print("wmdist: --games and --rollouts must be >= 1", file=sys.stderr)
        return 2
    for name, (win, block, centre) in PLAYERS.items():
        player = scripted(CONNECT4, win, block, centre, a.seed)
        opponent = MCTSOpponent(CONNECT4, a.rollouts, seed=a.seed + 1)
        out = np.array([play(CONNECT4, player, opponent.act, g % 2 == 0) for g in range(a.games)])
        print(json.dumps({"player": name, "opponent": f"UCT ({a.rollouts} rollouts per move)", "games": a.games,
                          "won": float(np.mean(out > 0)), "drawn": float(np.mean(out == 0)),
                          "lost": float(np.mean(out < 0))}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
