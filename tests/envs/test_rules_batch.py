"""The batched rules (`BatchRules.step`) agree with the one-game reference (`Game.apply`) on
every action of positions from random games, for both observation layouts."""
import numpy as np
import pytest

from wmdist.envs.boardgames.env import BoardEnv
from wmdist.envs.boardgames.game import CONNECT4, TICTACTOE, IllegalMove
from wmdist.envs.boardgames.rules_batch import ILLEGAL_REWARD, BatchRules


def _positions(game, n_games, rng):
    """Non-terminal states of random games (every position each game passes through)."""
    out = []
    for _ in range(n_games):
        s = game.initial()
        while not game.terminal(s):
            out.append(s)
            s = game.apply(s, rng.choice(np.flatnonzero(game.legal(s))))
    return out


@pytest.mark.parametrize("game", [TICTACTOE, CONNECT4], ids=lambda g: g.name)
@pytest.mark.parametrize("obs", ["vector", "planes"])
def test_every_action_matches_the_reference(game, obs):
    env = BoardEnv(game, obs=obs)
    rules = BatchRules(game, planes=obs == "planes")
    states = _positions(game, 30, np.random.default_rng(0))
    seen = {"win": 0, "draw": 0, "illegal": 0}
    for a in range(game.num_actions):
        batch = np.stack([env.observe(s) for s in states])
        st = rules.step(batch, np.zeros(len(states), bool), np.full(len(states), a))
        for i, s in enumerate(states):
            try:
                nxt = game.apply(s, a)
            except IllegalMove:
                seen["illegal"] += 1
                assert st.done[i] and st.reward[i] == ILLEGAL_REWARD and not st.legal[i].any()
                np.testing.assert_array_equal(st.obs[i], batch[i])  # the position is unchanged
                continue
            np.testing.assert_array_equal(st.obs[i], env.observe(nxt))  # the next mover's view
            assert st.reward[i] == game.reward(nxt)
            assert st.done[i] == game.terminal(nxt)
            np.testing.assert_array_equal(st.legal[i], game.legal(nxt))
            seen["win"] += nxt.winner >= 0
            seen["draw"] += game.terminal(nxt) and nxt.winner < 0
        np.testing.assert_array_equal(rules.legal(*rules.boards(batch)), np.stack([game.legal(s) for s in states]))
    assert seen["win"] > 0 and seen["illegal"] > 0  # both branches were exercised
    assert st.obs.dtype == batch.dtype


def test_an_ended_line_stays_ended_with_no_reward():
    rules = BatchRules(CONNECT4, planes=True)
    env = BoardEnv(CONNECT4, obs="planes")
    obs = env.observe(CONNECT4.initial())[None]
    st = rules.step(obs, np.array([True]), np.array([3]))
    assert st.done[0] and st.reward[0] == 0 and not st.legal[0].any()
    np.testing.assert_array_equal(st.obs, obs)
