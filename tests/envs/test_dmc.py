"""dm_control: few tests, each builds at most a couple of envs (building is ~1 s)."""
import numpy as np

from wmdist.envs import EnvConfig, make_env

from envs_helpers import assert_obs_matches_spec, rollout


def test_state_spaces_determinism_and_time_limit():
    cfg = EnvConfig(id="dmc:cartpole-balance", action_repeat=2, time_limit=6)
    with make_env(cfg, seed=1) as a, make_env(cfg, seed=1) as b:
        spec = a.spec
        assert spec.obs_shape == (5,) and spec.obs_dtype == "float32"  # position 3 + velocity 2
        assert spec.action_shape == (1,) and spec.action_low == (-1.0,) and spec.action_high == (1.0,)
        assert spec.max_episode_steps == 6 and a.legal_actions() is None
        oa, ra = rollout(a, 14, seed=None)
        ob, rb = rollout(b, 14, seed=None)
        np.testing.assert_array_equal(np.stack(oa), np.stack(ob))
        assert ra == rb and all(0.0 <= r <= 2.0 for r in ra)  # reward in [0, 1] per raw step
        for o in oa:
            assert_obs_matches_spec(a, o)
        a.reset(seed=9)
        truncs = [a.step(np.zeros(1, np.float32))[3] for _ in range(6)]
        assert truncs == [False] * 5 + [True]
        # reseeding changes the initial state; the same reseed reproduces it
        x = a.reset(seed=9)
        y = a.reset(seed=10)
        z = a.reset(seed=9)
        np.testing.assert_array_equal(x, z)
        assert not np.array_equal(x, y)


def test_default_time_limit_is_suite_steps_over_repeat():
    with make_env(EnvConfig(id="dmc:walker-walk", action_repeat=2), seed=0) as env:
        assert env.spec.max_episode_steps == 500 and env.spec.action_shape == (6,)


def test_pixels_render_on_cpu():
    cfg = EnvConfig(id="dmc:cartpole-swingup", pixels=True, image_size=64)
    with make_env(cfg, seed=0) as env:
        assert env.spec.obs_shape == (64, 64, 3) and env.spec.obs_kind == "image"
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        assert len(np.unique(obs.reshape(-1, 3), axis=0)) > 10  # a real picture, not one colour
        nxt, _, _, _ = env.step(np.ones(1, np.float32))
        assert nxt.shape == (64, 64, 3) and nxt.dtype == np.uint8
        frame = env.render()
        assert frame.shape == (64, 64, 3) and frame.dtype == np.uint8
