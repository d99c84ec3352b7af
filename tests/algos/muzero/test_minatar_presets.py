"""The MinAtar MuZero presets: the full-resolution grid network keeps 10x10 hidden planes,
and each preset (pUCT and Gumbel) runs self-play and learner updates in process."""
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.algos.muzero.loop import InProcessLoop
from wmdist.algos.muzero import MuZero
from wmdist.algos.muzero.build import build_net
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec

torch.set_num_threads(1)
CONFIGS = Path(__file__).resolve().parents[3] / "configs"


def test_grid_stem_keeps_the_10x10_grid():
    cfg = load_config(CONFIGS / "muzero_minatar_breakout.yaml")
    spec = env_spec(cfg.env)
    assert spec.obs_shape == (10, 10, 4) and spec.num_actions == 6
    net = build_net(spec, cfg.algo)
    obs = torch.randint(0, 2, (3, 10, 10, 4), dtype=torch.uint8) * 255
    with torch.no_grad():
        s, logits, _ = net.initial_inference(obs)
        s2, r, _, _ = net.recurrent_inference(s, torch.tensor([0, 3, 5]))
    assert s.shape == (3, cfg.algo.conv_channels, 10, 10) and s2.shape == s.shape
    assert logits.shape == (3, 6) and r.shape == (3, 2 * cfg.algo.reward_support + 1)
    # the paper's Atari stem would leave 1x1 planes: the preset's grid stem is what keeps the board
    atari = build_net(spec, load_config(CONFIGS / "muzero_minatar_breakout.yaml", ["algo.conv_stem=atari"]).algo)
    with torch.no_grad():
        assert atari.represent(obs).shape[-2:] == (1, 1)


@pytest.mark.parametrize("name", ["muzero_minatar_breakout", "muzero_minatar_asterix", "muzero_gumbel_minatar_breakout"])
def test_preset_self_play_and_updates(name):
    cfg = load_config(CONFIGS / f"{name}.yaml")
    assert (cfg.run.max_env_steps, cfg.run.max_minutes) == (100_000, 45)
    if "gumbel" in name:
        assert cfg.algo.search.gumbel and 4 <= cfg.algo.search.num_simulations <= 8
    spec = env_spec(cfg.env)
    algo = MuZero(spec, cfg.algo, seed=0)
    loop = InProcessLoop(algo, cfg.env, num_envs=2, seq_len=cfg.replay.seq_len, overlap=cfg.replay.overlap)
    loop.collect(60)
    assert loop.env_steps == 120 and loop.sequences
    metrics = loop.train(3, 8)
    assert all(np.isfinite(m["loss"]) for m in metrics)
