import numpy as np

from wmdist.envs import EnvConfig, make_env

from envs_helpers import assert_obs_matches_spec


def test_pong_reset_steps_and_shapes():
    with make_env(EnvConfig(id="atari:Pong"), seed=0) as env:
        spec = env.spec
        assert spec.obs_shape == (84, 84, 4) and spec.obs_dtype == "uint8" and spec.obs_kind == "image"
        assert spec.num_actions == 6 and spec.max_episode_steps == 27000
        obs = env.reset()
        assert_obs_matches_spec(env, obs)
        # after reset the stack is the reset frame repeated
        assert all(np.array_equal(obs[..., 0], obs[..., k]) for k in range(4))
        frames = [obs]
        for t in range(40):
            obs, r, term, trunc = env.step(t % 6)
            assert_obs_matches_spec(env, obs)
            assert r in (-1.0, 0.0, 1.0) and not term and not trunc
            frames.append(obs)
        # the stack shifts: the newest frame of step t is the second newest at step t+1
        np.testing.assert_array_equal(frames[-2][..., 3], frames[-1][..., 2])
        assert env.render().shape == (210, 160, 3)


def test_pong_same_seed_same_frames_and_rgb_stack():
    cfg = EnvConfig(id="atari:Pong", grayscale=False, frame_stack=2, screen_size=64, sticky_actions=0.25)
    with make_env(cfg, seed=7) as a, make_env(cfg, seed=7) as b:
        assert a.spec.obs_shape == (64, 64, 6)
        oa, ob = a.reset(), b.reset()
        for t in range(25):
            oa, ob = a.step(t % 6)[0], b.step(t % 6)[0]
        np.testing.assert_array_equal(oa, ob)
        assert oa.shape == (64, 64, 6) and len(np.unique(oa)) > 3


def test_episode_cap_truncates():
    with make_env(EnvConfig(id="atari:Pong", max_episode_frames=40, noop_max=0), seed=0) as env:
        assert env.spec.max_episode_steps == 10
        env.reset()
        truncs = [env.step(0)[3] for _ in range(10)]
        assert truncs[-1] and not any(truncs[:-1])


def test_life_loss_ends_episode_and_reset_continues_the_game():
    with make_env(EnvConfig(id="atari:Breakout", terminal_on_life_loss=True), seed=0) as env:
        ale = env._env.unwrapped.ale  # peek at the emulator's life counter
        env.reset()
        assert ale.lives() == 5
        for t in range(500):  # FIRE launches the ball; alternating with RIGHT soon misses it
            _, _, term, trunc = env.step(1 if t % 2 == 0 else 2)
            if term or trunc:
                break
        assert term and not trunc and ale.lives() == 4
        env.reset()
        assert ale.lives() == 4  # same game, next life
        env.reset()
        assert ale.lives() == 5  # a reset that follows no life loss restarts the game
