"""Tic-tac-toe: the policy stores legal masks and the player to move, searches only legal
moves, and the learner's value targets are the final outcome seen by the player to move."""
import numpy as np
import torch

from tests.algos.muzero.loop import InProcessLoop
from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.algos.muzero.targets import make_targets, sample_starts
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec
from wmdist.search.api import SearchConfig

torch.set_num_threads(1)
ENV = EnvConfig(id="board:tictactoe")


def _loop(seed=0):
    cfg = MuZeroConfig(search=SearchConfig(num_simulations=8, discount=1.0, dirichlet_alpha=0.3),
                       latent_dim=16, hidden=[32], value_support=1, reward_support=1, td_steps=9,
                       temperature_moves=9)
    algo = MuZero(env_spec(ENV), cfg, seed=seed)
    return algo, InProcessLoop(algo, ENV, num_envs=8, seq_len=10, overlap=0, seed=seed)


def test_extras_hold_legal_moves_and_player_to_move():
    algo, loop = _loop()
    assert set(algo.extra_fields()) == {"search_policy", "search_value", "legal", "to_play"}
    loop.collect(30)
    seqs = [w for w, n in loop.sequences]
    assert len(seqs) >= 8
    for w in seqs:
        acting = ~w["last"] & (w["legal"].any(-1))
        n_act = int(acting.sum())
        assert n_act >= 5  # a game lasts at least 5 moves
        # players alternate from 0, and the search never puts mass on an occupied square
        assert (w["to_play"][:n_act] == np.arange(n_act) % 2).all()
        assert (w["search_policy"][:n_act][~w["legal"][:n_act]] == 0).all()
        np.testing.assert_allclose(w["search_policy"][:n_act].sum(-1), 1.0, atol=1e-5)
        own = w["obs"][:n_act].reshape(n_act, 3, 9)[:, :2].sum(1)  # occupied squares in the obs
        assert (w["legal"][:n_act] == (own == 0)).all()
        assert w["legal"][np.arange(n_act), w["action"][:n_act]].all()  # every move played was legal


def test_value_targets_are_outcome_for_player_to_move():
    algo, loop = _loop(seed=1)
    loop.collect(40)
    batch = loop.sample(64)
    rng = np.random.default_rng(0)
    t0, valid = sample_starts(batch["mask"], batch["last"], rng)
    tg = make_targets(batch, t0, valid, 5, 9, -1.0, 9, rng)
    z = tg.value_target(np.zeros_like(tg.value_partial))
    assert (tg.boot_idx == -1).all()  # every game ends inside its window: pure outcomes
    checked = 0
    for b in range(64):
        end = int(np.flatnonzero(batch["last"][b])[0])
        winner = None if batch["reward"][b, end] == 0 else int(batch["to_play"][b, end - 1])
        for k in range(6):
            p = t0[b] + k
            if p >= end or tg.value_w[b, k] == 0:
                continue
            mover = int(batch["to_play"][b, p])
            want = 0.0 if winner is None else (1.0 if mover == winner else -1.0)
            assert z[b, k] == want
            checked += 1
    assert checked > 100
