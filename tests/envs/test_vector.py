import numpy as np
import pytest

from wmdist.envs import Env, EnvConfig, EnvSpec, VectorEnv, make_env, make_vector_env


class Countdown(Env):
    """Fake env isolating VectorEnv's bookkeeping: obs = [episode, t], ends after `length` steps."""

    def __init__(self, length: int, truncate: bool = False) -> None:
        self.spec = EnvSpec(id="fake:countdown", obs_shape=(2,), obs_dtype="float32", obs_kind="vector", num_actions=3)
        self.length, self.truncate = length, truncate
        self.episode, self.t, self.seeds = -1, 0, []

    def reset(self, seed=None):
        self.seeds.append(seed)
        self.episode, self.t = self.episode + 1, 0
        return np.array([self.episode, 0], np.float32)

    def step(self, action):
        self.t += 1
        end = self.t >= self.length
        return np.array([self.episode, self.t], np.float32), float(action), end and not self.truncate, end and self.truncate

    def legal_actions(self):
        return np.array([True, True, self.t == 0])  # action 2 only at an episode's start

    def render(self):
        return np.zeros((4, 4, 3), np.uint8)


def test_same_step_auto_reset_bookkeeping():
    envs = [Countdown(2), Countdown(3, truncate=True)]
    vec = VectorEnv([lambda e=e: e for e in envs], seed=10)
    s = vec.reset()
    assert envs[0].seeds == [10] and envs[1].seeds == [11]  # env i gets seed + i
    assert s.first.all() and (s.reward == 0).all() and s.to_play is None
    np.testing.assert_array_equal(s.final_obs, s.obs)
    s = vec.step(np.array([1, 2]))
    assert s.reward.dtype == np.float32 and s.reward.tolist() == [1.0, 2.0] and not s.first.any()
    s = vec.step(np.array([1, 1]))  # env 0 terminates on its 2nd step
    assert s.terminated.tolist() == [True, False] and s.truncated.tolist() == [False, False]
    assert s.first.tolist() == [True, False]
    np.testing.assert_array_equal(s.final_obs[0], [0, 2])  # last obs of the ended episode
    np.testing.assert_array_equal(s.obs[0], [1, 0])  # already the next episode's first obs
    np.testing.assert_array_equal(s.final_obs[1], s.obs[1])
    assert s.legal.shape == (2, 3) and s.legal[:, 2].tolist() == [True, False]  # legal for the new obs
    s = vec.step(np.array([0, 0]))  # env 1 truncates on its 3rd step
    assert s.truncated.tolist() == [False, True] and s.first.tolist() == [False, True]
    assert envs[0].seeds == [10, None] and envs[1].seeds == [11, None]  # auto-resets continue the stream
    with pytest.raises(ValueError, match=r"actions must have shape \(2,\)"):
        vec.step(np.array([0, 0, 0]))


def test_errors_before_reset_and_bad_arguments():
    vec = VectorEnv([lambda: Countdown(2)])
    with pytest.raises(RuntimeError, match="before reset"):
        vec.step(np.array([0]))
    with pytest.raises(ValueError, match="either env_fns or"):
        VectorEnv()
    with pytest.raises(ValueError, match="num_envs must be an int >= 1"):
        make_vector_env(EnvConfig(), 0, seed=0)


def test_vector_cartpole_matches_single_envs_and_is_deterministic():
    cfg = EnvConfig(id="gym:CartPole-v1")
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 2, size=(60, 3))

    def run():
        vec = make_vector_env(cfg, 3, seed=5)
        steps = [vec.reset()] + [vec.step(a) for a in actions]
        vec.close()
        return steps

    a, b = run(), run()
    for sa, sb in zip(a, b):
        np.testing.assert_array_equal(sa.obs, sb.obs)
        np.testing.assert_array_equal(sa.first, sb.first)
    assert a[0].obs.shape == (3, 4) and a[0].obs.dtype == np.float32 and a[0].legal.all()
    assert sum(s.first.sum() for s in a[1:]) > 0  # random CartPole episodes end within 60 steps
    with make_env(cfg, seed=6) as single:  # env 1 of the vector == a single env seeded 5 + 1
        np.testing.assert_array_equal(single.reset(), a[0].obs[1])
        for t, act in enumerate(actions[:5]):
            np.testing.assert_array_equal(single.step(act[1])[0], a[t + 1].final_obs[1])


def test_vector_board_games_report_legal_and_to_play():
    vec = make_vector_env(EnvConfig(id="board:tictactoe"), 2, seed=0)
    s = vec.reset()
    assert s.to_play.tolist() == [0, 0] and s.legal.shape == (2, 9) and s.legal.all()
    for a in (0, 3, 1, 4):
        s = vec.step(np.array([a, 8 - a]))
    assert s.to_play.tolist() == [0, 0] and not s.legal[0, 0] and not s.legal[1, 8]
    before = [e.state for e in vec.envs]
    with pytest.raises(ValueError, match="illegal action 0 for env 0 .*no env was stepped"):
        vec.step(np.array([0, 2]))  # env 0's cell 0 is taken; env 1's move is fine
    with pytest.raises(ValueError, match=r"action 9 of env 1 out of range \[0, 9\)"):
        vec.step(np.array([2, 9]))
    with pytest.raises(ValueError, match="must be integers"):
        vec.step(np.array([2.0, 6.0]))
    assert [e.state for e in vec.envs] == before
    s = vec.step(np.array([2, 6]))  # both complete a row: player 0 wins, boards auto-reset
    assert s.reward.tolist() == [1.0, 1.0] and s.terminated.all() and s.first.all()
    assert s.to_play.tolist() == [0, 0] and s.legal.all() and s.final_obs[0, 18:].sum() == 9
    vec.close()


def test_continuous_vector_has_no_legal_mask():
    vec = make_vector_env(EnvConfig(id="gym:Pendulum-v1"), 2, seed=0)
    s = vec.reset()
    assert s.legal is None and s.to_play is None
    s = vec.step(np.zeros((2, 1), np.float32))
    assert s.obs.shape == (2, 3) and s.reward.shape == (2,)
    vec.close()
