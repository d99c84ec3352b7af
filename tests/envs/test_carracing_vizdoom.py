"""The World Models env families: carracing:CarRacing-v3 and vizdoom:TakeCover at 64x64."""
import numpy as np
import pytest

from wmdist.envs import EnvConfig, check_id, list_families, make_env

from envs_helpers import assert_obs_matches_spec


def test_ids_listed_and_bad_name_is_one_line():
    fams = dict(list_families())
    assert "carracing" in fams and "vizdoom" in fams
    assert check_id("carracing:CarRacing-v3") == "carracing:CarRacing-v3"
    assert check_id("vizdoom:TakeCover") == "vizdoom:TakeCover"
    with pytest.raises(ValueError, match="closest match: 'vizdoom:TakeCover'") as err:
        check_id("vizdoom:TakeCovr")
    assert "\n" not in str(err.value)


def test_carracing_64x64_continuous():
    with make_env(EnvConfig(id="carracing:CarRacing-v3", time_limit=5), seed=0) as env:
        s = env.spec
        assert s.obs_shape == (64, 64, 3) and s.obs_dtype == "uint8" and s.action_shape == (3,)
        assert s.action_low == (-1.0, 0.0, 0.0) and s.action_high == (1.0, 1.0, 1.0) and s.max_episode_steps == 5
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        assert obs.std() > 5  # a real picture (track and grass), not a blank frame
        for t in range(5):
            obs, r, term, trunc = env.step(np.array([0.0, 1.0, 0.0], np.float32))
            assert_obs_matches_spec(env, obs)
        assert trunc and not term
        assert env.render().shape == (400, 600, 3)  # gymnasium's full-size view, for videos


def test_takecover_survival_reward_and_seeded_replay():
    def play(seed):
        with make_env(EnvConfig(id="vizdoom:TakeCover"), seed=seed) as env:
            assert env.spec.num_actions == 3 and env.spec.obs_shape == (64, 64, 3)
            assert env.spec.max_episode_steps == 2100  # the paper's cap
            obs, total, n, frames = env.reset(), 0.0, 0, []
            assert_obs_matches_spec(env, obs)
            while True:
                obs, r, term, trunc = env.step(n % 3)
                frames.append(obs)
                total, n = total + r, n + 1
                if term or trunc:
                    return total, n, np.stack(frames)
    total, n, frames = play(3)
    assert total == n  # +1 per step survived
    assert 10 < n < 2100
    total2, n2, frames2 = play(3)
    assert n2 == n and np.array_equal(frames, frames2)
