"""Presets load through the config loader with the paper's numbers; the dream GIF is written."""
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer, DreamerConfig
from wmdist.algos.dreamer.config import VERSION_DEFAULTS
from wmdist.algos.dreamer.dream import open_loop_video
from wmdist.config.loader import load_config
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import make_env

CONFIGS = Path(__file__).resolve().parents[3] / "configs"
PRESETS = ["dreamerv1_dmc_cartpole_balance", "dreamerv2_dmc_cartpole_balance", "dreamerv3_dmc_cartpole_balance",
           "dreamerv3_cartpole", "dreamerv3_dmc_pixels"]


# deliberate, commented departures from a version's numbers (the reason is in the preset)
DEVIATIONS = {"dreamerv1_dmc_cartpole_balance": ("free_nats", "slow_critic")}  # from state the KL sits below 3 nats;
#   a V2-style target critic steadies V1's returns

@pytest.mark.parametrize("name", PRESETS)
def test_preset_loads_and_keeps_version_numbers(name):
    cfg = load_config(CONFIGS / f"{name}.yaml")
    assert cfg.algo_name == "dreamer"
    algo = cfg.algo.resolved()
    v = VERSION_DEFAULTS[algo.version]
    for key in ("kl_dyn", "kl_rep", "free_nats", "reward_head", "critic_head", "unimix", "slow_critic"):
        if key in DEVIATIONS.get(name, ()):
            continue
        assert getattr(algo, key) == v[key], key
    assert cfg.replay.overlap == 0  # so samples_per_insert is the train ratio


def test_version_defaults_fill_only_unset_fields():
    cfg = DreamerConfig(version=2, kl_dyn=0.7).resolved()
    assert cfg.kl_dyn == 0.7 and cfg.kl_rep == 0.2 and cfg.classes == 32 and cfg.unimix == 0.0
    v3 = DreamerConfig(version=3, size="xs").resolved()
    assert (v3.deter, v3.units, v3.cnn_depth, v3.mlp_layers) == (256, 256, 24, 1)
    assert v3.free_nats == 1.0 and v3.discount == 0.997 and v3.bins == 255
    with pytest.raises(ValueError, match="return_low"):
        DreamerConfig(return_low=0.9, return_high=0.1).resolved()


def test_open_loop_video_vector(tmp_path):
    env = make_env(EnvConfig(id="gym:CartPole-v1"), 0)
    algo = Dreamer(env.spec, tiny_config(3))
    weights = algo.make_learner().get_weights()
    out = open_loop_video(algo, weights, env, str(tmp_path / "dream.gif"), context=5, horizon=10)
    frames = imageio.mimread(out)
    assert 6 <= len(frames) <= 15  # CartPole may end early under an untrained policy
    assert frames[0].shape[0] == 8 * (2 * 4 + 1)  # 4 real rows + separator + 4 predicted rows, x8
    assert not np.array_equal(frames[0], frames[-1])  # the strip grows over time


def test_open_loop_video_pixels(tmp_path):
    from wmdist.envs.spec import EnvSpec

    class Blink:  # a tiny image env: 64x64 frames with a moving square
        spec = EnvSpec("test:blink", (64, 64, 3), "uint8", "image", action_shape=(1,), action_low=(-1.0,), action_high=(1.0,))

        def reset(self, seed=None):
            self.t = 0
            return self._obs()

        def _obs(self):
            img = np.zeros((64, 64, 3), np.uint8)
            img[self.t % 60:self.t % 60 + 4, 10:14] = 255
            return img

        def step(self, a):
            self.t += 1
            return self._obs(), 0.0, False, False

        def legal_actions(self):
            return None

    algo = Dreamer(Blink.spec, tiny_config(3, cnn_depth=4))
    out = open_loop_video(algo, algo.make_learner().get_weights(), Blink(), str(tmp_path / "px.gif"), context=2, horizon=3)
    frames = imageio.mimread(out)
    assert len(frames) == 5 and frames[0].shape[:2] == (256, 512)  # real | model, x4


@pytest.mark.parametrize("name", PRESETS)
def test_preset_model_takes_an_update(name):
    """Each preset's networks (on a stand-in spec of the same kind) do one finite update."""
    from wmdist.bench.dreamer import bench_spec, random_batch
    from wmdist.envs.spec import EnvSpec

    cfg = load_config(CONFIGS / f"{name}.yaml")
    if cfg.env.pixels:
        spec = EnvSpec("px", (64, 64, 3), "uint8", "image", action_shape=(1,), action_low=(-1.0,), action_high=(1.0,))
        batch = random_batch(bench_spec(False), 2, 6)
        batch["obs"] = np.random.default_rng(0).integers(0, 255, (2, 6, 64, 64, 3)).astype(np.uint8)
    else:
        spec = bench_spec("CartPole" in cfg.env.id)
        batch = random_batch(spec, 2, 6)
    res = Dreamer(spec, cfg.algo).make_learner().update(batch)
    assert np.isfinite(res.metrics["model_loss"]) and res.metrics["model_loss"] > 0
