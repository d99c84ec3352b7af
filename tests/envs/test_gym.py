import numpy as np
import pytest

from wmdist.envs import EnvConfig, make_env

from envs_helpers import assert_obs_matches_spec, rollout


def test_cartpole_spaces_and_steps():
    with make_env(EnvConfig(id="gym:CartPole-v1"), seed=0) as env:
        assert env.spec.num_actions == 2 and env.spec.players == 1 and env.spec.max_episode_steps == 500
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        assert env.legal_actions().tolist() == [True, True] and env.to_play() == 0
        done, n = False, 0
        while not done:
            obs, r, term, trunc = env.step(np.int64(0))  # always push left: falls quickly
            assert_obs_matches_spec(env, obs)
            assert r == 1.0
            done, n = term or trunc, n + 1
        assert term and not trunc and n < 50


def test_same_seed_same_trajectory_other_seed_differs():
    cfg = EnvConfig(id="gym:Pendulum-v1")
    with make_env(cfg, seed=3) as a, make_env(cfg, seed=3) as b, make_env(cfg, seed=4) as c:
        oa, ra = rollout(a, 30, seed=None)
        ob, rb = rollout(b, 30, seed=None)
        oc, _ = rollout(c, 30, seed=None)
    np.testing.assert_array_equal(np.stack(oa), np.stack(ob))
    assert ra == rb
    assert not np.array_equal(oa[0], oc[0])


def test_action_repeat_and_time_limit():
    cfg = EnvConfig(id="gym:Pendulum-v1", action_repeat=4, time_limit=3)
    with make_env(cfg, seed=0) as env:
        assert env.spec.max_episode_steps == 3
        env.reset()
        ends = [env.step(np.zeros(1, np.float32))[3] for _ in range(3)]
        assert ends == [False, False, True]  # truncated after 3 agent steps (12 raw steps)

    # The repeated step's reward is the sum over the 4 raw steps (same seed, same actions).
    zero = np.zeros(1, np.float32)
    with make_env(EnvConfig(id="gym:Pendulum-v1", action_repeat=4), 5) as rep, make_env(
        EnvConfig(id="gym:Pendulum-v1"), 5
    ) as raw:
        rep.reset(), raw.reset()
        obs4, r4, _, _ = rep.step(zero)
        steps = [raw.step(zero) for _ in range(4)]
    assert r4 == pytest.approx(sum(s[1] for s in steps))
    np.testing.assert_array_equal(obs4, steps[-1][0])


def test_continuous_actions_are_checked_and_clipped():
    with make_env(EnvConfig(id="gym:Pendulum-v1"), seed=0) as env:
        env.reset()
        with pytest.raises(ValueError, match=r"must have shape \(1,\)"):
            env.step(np.zeros(2, np.float32))
        env.step(np.array([50.0], np.float32))  # clipped to the bound, no error


def test_discrete_action_out_of_range():
    with make_env(EnvConfig(), seed=0) as env:
        env.reset()
        with pytest.raises(ValueError, match=r"action 2 out of range \[0, 2\)"):
            env.step(2)


def test_discrete_observation_is_one_hot():
    with make_env(EnvConfig(id="gym:FrozenLake-v1"), seed=0) as env:
        obs = env.reset()
        assert obs.shape == (16,) and obs.dtype == np.float32 and obs.sum() == 1.0 and obs[0] == 1.0
