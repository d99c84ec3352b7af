import numpy as np
import pytest

from wmdist.envs import EnvConfig, check_id, list_families, make_env
from wmdist.envs.minatar import minatar_games

from envs_helpers import assert_obs_matches_spec, rollout


def test_ids_listed_and_bad_name_is_one_line():
    assert "minatar" in dict(list_families())
    assert minatar_games() == ["Asterix", "Breakout", "Freeway", "Seaquest", "SpaceInvaders"]
    for game in minatar_games():
        assert check_id(f"minatar:{game}") == f"minatar:{game}"
    with pytest.raises(ValueError, match="closest match: 'minatar:Breakout'") as err:
        check_id("minatar:breakot")
    assert "\n" not in str(err.value)
    # wmdist drives minatar.Environment itself: the package's gymnasium ids stay unregistered
    import gymnasium as gym

    make_env(EnvConfig(id="minatar:Breakout"), seed=0).close()
    assert not any(k.startswith("MinAtar/") for k in gym.registry)


@pytest.mark.parametrize("game,channels", [("Breakout", 4), ("Asterix", 4), ("Seaquest", 10),
                                           ("Freeway", 7), ("SpaceInvaders", 6)])
def test_image_spaces_defaults_full_action_set(game, channels):
    with make_env(EnvConfig(id=f"minatar:{game}"), seed=0) as env:
        spec = env.spec
        assert spec.obs_shape == (10, 10, channels) and spec.obs_dtype == "uint8" and spec.obs_kind == "image"
        assert spec.num_actions == 6  # full action set by default (MinAtar paper)
        assert env._env.sticky_action_prob == 0.1
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        assert set(np.unique(obs)) <= {0, 255} and obs.max() == 255
        for t in range(20):
            obs, r, term, trunc = env.step(t % 6)
            assert_obs_matches_spec(env, obs)
            if term:
                break
        assert env.render().shape == (160, 160, 3)


def test_vector_obs_minimal_actions_and_no_sticky():
    cfg = EnvConfig(id="minatar:Breakout", minatar_obs="vector", minatar_full_action_set=False,
                    minatar_sticky_actions=0.0)
    with make_env(cfg, seed=0) as env:
        assert env.spec.obs_shape == (400,) and env.spec.obs_dtype == "float32" and env.spec.obs_kind == "vector"
        assert env.spec.num_actions == 3  # Breakout's minimal set: no-op, left, right
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        assert set(np.unique(obs)) <= {0.0, 1.0}
        # index 1 is "left" in the minimal set: the paddle (channel 0, bottom row) moves left
        grid = obs.reshape(10, 10, 4)
        x0 = int(np.flatnonzero(grid[9, :, 0])[0])
        x1 = int(np.flatnonzero(env.step(1)[0].reshape(10, 10, 4)[9, :, 0])[0])
        assert x1 == max(0, x0 - 1)


def test_same_seed_same_trajectory_other_seed_differs():
    cfg = EnvConfig(id="minatar:Breakout")
    with make_env(cfg, seed=3) as a, make_env(cfg, seed=3) as b, make_env(cfg, seed=4) as c:
        oa, ra = rollout(a, 300, seed=3)
        ob, rb = rollout(b, 300, seed=3)
        oc, _ = rollout(c, 300, seed=4)
        assert ra == rb and all(np.array_equal(x, y) for x, y in zip(oa, ob))
        assert not all(np.array_equal(x, y) for x, y in zip(oa, oc))
        assert sum(ra) > 0  # random play breaks some bricks in 300 steps


def test_sticky_actions_repeat_the_previous_action():
    # With probability 1 every action is the previous one (initially no-op): the paddle never moves.
    with make_env(EnvConfig(id="minatar:Breakout", minatar_sticky_actions=1.0), seed=0) as env:
        obs = env.reset()
        paddle = obs[9, :, 0].copy()
        for _ in range(5):
            obs, _, term, _ = env.step(1)  # "left"
        assert np.array_equal(obs[9, :, 0], paddle)


def test_time_limit_and_bad_config():
    with make_env(EnvConfig(id="minatar:Freeway", time_limit=5), seed=0) as env:
        env.reset()
        truncs = [env.step(0)[3] for _ in range(5)]
        assert truncs[-1] and not any(truncs[:-1])
    with pytest.raises(ValueError, match="env.minatar_obs must be one of"):
        make_env(EnvConfig(id="minatar:Breakout", minatar_obs="pixels"), seed=0)
    with pytest.raises(ValueError, match="action_repeat must be 1"):
        make_env(EnvConfig(id="minatar:Breakout", action_repeat=2), seed=0)
