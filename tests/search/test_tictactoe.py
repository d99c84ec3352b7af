"""With the exact tic-tac-toe rules as the model, search wins or blocks as the solver says."""
from __future__ import annotations

import itertools

import numpy as np

from wmdist.search.api import SearchConfig, search
from wmdist.search.testing import TicTacToeModel, move_values, solve, winner_is_mover


def _positions():
    """All reachable non-terminal boards (mover's view) with 3-6 stones, split into
    'win now' (an immediate win exists) and 'only block' (no win; exactly one move avoids a loss)."""
    wins, blocks = [], []
    for cells in itertools.product((0, 1, -1), repeat=9):
        own, opp = cells.count(1), cells.count(-1)
        if not (opp == own and 2 <= own <= 3 or opp == own + 1 and 2 <= own <= 3):
            continue
        board = np.array([cells])
        if winner_is_mover(board)[0] or winner_is_mover(-board)[0]:
            continue
        values = move_values(cells)
        immediate = [a for a, v in values.items() if v == 1 and _wins_now(cells, a)]
        if immediate:
            wins.append(cells)
        elif sum(v >= 0 for v in values.values()) == 1 and solve(cells) == 0:
            blocks.append(cells)
    return wins, blocks


def _wins_now(cells, a):
    after = np.array([cells])
    after[0, a] = 1
    return bool(winner_is_mover(after)[0])


def test_search_plays_the_winning_move_or_the_only_block() -> None:
    wins, blocks = _positions()
    assert len(wins) > 100 and len(blocks) > 20
    rng = np.random.default_rng(0)
    chosen = [wins[i] for i in rng.choice(len(wins), 24, replace=False)]
    chosen += [blocks[i] for i in rng.choice(len(blocks), 24, replace=False)]
    boards = np.array(chosen, dtype=np.int8)
    batch = len(boards)
    latent = np.concatenate([boards, np.zeros((batch, 1), np.int8)], axis=1)
    legal = boards == 0
    config = SearchConfig(num_simulations=300, discount=1.0)
    out = search(latent, TicTacToeModel.logits(boards), np.zeros(batch), legal, np.arange(batch) % 2, TicTacToeModel(),
                 config, rng, temperature=0.0, add_noise=False, two_player=True)
    for b, cells in enumerate(chosen):
        values = move_values(cells)
        best = max(values.values())
        assert values[int(out.action[b])] == best, (cells, out.visit_counts[b])
        if b < 24:
            assert out.root_value[b] > 0.5  # a found win shows in the search value
    # Gumbel search (few simulations) also finds them.
    gcfg = SearchConfig(num_simulations=64, discount=1.0, gumbel=True)
    gout = search(latent, TicTacToeModel.logits(boards), np.zeros(batch), legal, None, TicTacToeModel(), gcfg, rng,
                  add_noise=False, two_player=True)
    for b, cells in enumerate(chosen):
        values = move_values(cells)
        assert values[int(gout.action[b])] == max(values.values()), (cells, gout.visit_counts[b])
