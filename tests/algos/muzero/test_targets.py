"""n-step value, reward and policy targets against a plain-loop reference, across episode
ends (terminal and truncated), padding and window ends; two-player sign flips."""
import numpy as np
import pytest

from tests.algos.muzero.helpers import random_batch
from wmdist.algos.muzero.targets import make_targets, sample_starts


def reference(batch, t0, k_steps, n, gamma, net_value):
    """Walk each (row, k) step by step. net_value[b, i] stands in for a network's value."""
    b_size, t = batch["mask"].shape
    out = {name: np.zeros((b_size, k_steps + 1)) for name in ("z", "vw", "r", "rw", "pw")}
    for b in range(b_size):
        # the episode's extent inside the window
        e, ended = t0[b], False
        while True:
            if batch["last"][b, e]:
                ended = True
                break
            if e + 1 >= t or not batch["mask"][b, e + 1] or batch["first"][b, e + 1]:
                break
            e += 1
        terminal = ended and batch["terminal"][b, e]
        for k in range(k_steps + 1):
            p = t0[b] + k
            if p > e:  # past the known data: absorbing after a terminal, unknown otherwise
                out["vw"][b, k] = out["rw"][b, k] = float(terminal)
                if k == 0:
                    out["rw"][b, k] = 0
                continue
            if k > 0:
                out["r"][b, k], out["rw"][b, k] = batch["reward"][b, p], 1.0
            if ended and p == e:
                out["vw"][b, k] = float(terminal)  # terminal value 0; truncated unknown
                continue
            out["pw"][b, k] = 1.0
            out["vw"][b, k] = 1.0
            g, disc, i = 0.0, 1.0, p
            for _ in range(n):
                if i == e:
                    break
                i += 1
                g += disc * batch["reward"][b, i]
                disc *= gamma
                if batch["last"][b, i]:
                    break
            if not (batch["last"][b, i] and batch["terminal"][b, i]):
                v = net_value[b, i] if batch["last"][b, i] else batch["search_value"][b, i]
                g += disc * v
            out["z"][b, k] = g
    return out


@pytest.mark.parametrize("gamma,n,k_steps", [(0.9, 3, 5), (0.997, 10, 5), (-1.0, 9, 5), (0.5, 1, 2)])
def test_targets_match_plain_loop(gamma, n, k_steps):
    rng = np.random.default_rng(0)
    for trial in range(20):
        batch = random_batch(rng, b=16, t=int(rng.integers(3, 14)), a=3)
        t0, valid = sample_starts(batch["mask"], batch["last"], rng)
        assert valid.all()
        net_value = rng.normal(size=batch["mask"].shape)
        tg = make_targets(batch, t0, valid, k_steps, n, gamma, 3, rng)
        # fill bootstrap values the way the learner does (search_value mode)
        rows = np.arange(16)[:, None]
        bi = np.clip(tg.boot_idx, 0, None)
        boot = np.where(tg.boot_net, net_value[rows, bi], batch["search_value"][rows, bi])
        z = tg.value_target(boot)
        ref = reference(batch, t0, k_steps, n, gamma, net_value)
        np.testing.assert_allclose(tg.value_w, ref["vw"], err_msg=f"trial {trial}")
        np.testing.assert_allclose(z * tg.value_w, ref["z"] * ref["vw"], rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(tg.reward_w, ref["rw"])
        np.testing.assert_allclose(tg.reward * tg.reward_w, ref["r"] * ref["rw"], rtol=1e-6)
        np.testing.assert_allclose(tg.policy_w, ref["pw"])
        # stored actions where an action was taken, any legal index elsewhere
        acting = tg.policy_w[:, :-1] > 0
        stored = batch["action"][rows, np.clip(t0[:, None] + np.arange(k_steps), 0, batch["mask"].shape[1] - 1)]
        assert (tg.actions[acting] == stored[acting]).all()
        assert tg.actions.min() >= 0 and tg.actions.max() < 3


def test_terminal_hand_example():
    """One episode 0..3 ending in a terminal at 3: z_1 = r2 + g r3 (no bootstrap), z_3 = 0."""
    batch = {
        "reward": np.array([[0.0, 1.0, 2.0, 4.0, 0.0, 0.0]], np.float32),
        "mask": np.array([[1, 1, 1, 1, 0, 0]], bool),
        "last": np.array([[0, 0, 0, 1, 0, 0]], bool),
        "terminal": np.array([[0, 0, 0, 1, 0, 0]], bool),
        "first": np.array([[1, 0, 0, 0, 0, 0]], bool),
        "search_policy": np.full((1, 6, 2), 0.5, np.float32),
        "search_value": np.array([[10.0, 20.0, 30.0, 0, 0, 0]], np.float32),
        "action": np.zeros((1, 6), np.int64),
    }
    tg = make_targets(batch, np.array([1]), np.array([True]), 3, 2, 0.5, 2, np.random.default_rng(0))
    z = tg.value_target(np.array([[30.0, 0.0, 0.0, 0.0]]))
    # k=0 (t=1): r2 + 0.5 r3 = 2 + 2 = 4, terminal reached in 2 steps: no bootstrap
    # k=1 (t=2): r3 = 4; k=2 (t=3): terminal, 0 weighted; k=3: absorbing, 0 weighted
    np.testing.assert_allclose(z[0] * tg.value_w[0], [4.0, 4.0, 0.0, 0.0])
    np.testing.assert_allclose(tg.value_w[0], [1, 1, 1, 1])
    np.testing.assert_allclose(tg.reward[0], [0, 2.0, 4.0, 0.0])
    np.testing.assert_allclose(tg.reward_w[0], [0, 1, 1, 1])
    np.testing.assert_allclose(tg.policy_w[0], [1, 1, 0, 0])


def test_two_player_outcome_from_player_to_move():
    """Tic-tac-toe style: 5 plies, the mover of ply 5 wins (+1 for the mover). With gamma=-1
    and n >= game length, z_t = +1 where the winner is to move and -1 where the loser is."""
    t = 6
    batch = {
        "reward": np.array([[0, 0, 0, 0, 0, 1.0]], np.float32),
        "mask": np.ones((1, t), bool),
        "last": np.array([[0, 0, 0, 0, 0, 1]], bool),
        "terminal": np.array([[0, 0, 0, 0, 0, 1]], bool),
        "first": np.array([[1, 0, 0, 0, 0, 0]], bool),
        "search_policy": np.full((1, t, 9), 1 / 9, np.float32),
        "search_value": np.zeros((1, t), np.float32),
        "action": np.zeros((1, t), np.int64),
    }
    tg = make_targets(batch, np.array([0]), np.array([True]), 5, 9, -1.0, 9, np.random.default_rng(0))
    z = tg.value_target(np.zeros((1, 6)))
    # player 0 moves at plies 0, 2, 4 (and wins with ply 4 -> reward on obs 5)
    np.testing.assert_allclose(z[0], [1, -1, 1, -1, 1, 0])
    assert (tg.boot_idx[0, :5] == -1).all()  # every target is the final outcome
