"""Every MuZero preset loads and validates; the Atari preset's conv network runs self-play
and learner updates on Pong (shrunk so it fits the CI budget)."""
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.algos.muzero.loop import InProcessLoop
from wmdist.algos.muzero import MuZero
from wmdist.algos.muzero.networks_conv import ConvNet
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec

torch.set_num_threads(1)
CONFIGS = Path(__file__).resolve().parents[3] / "configs"
PRESETS = ["muzero_cartpole", "muzero_tictactoe", "muzero_reanalyze_cartpole", "muzero_atari"]


@pytest.mark.parametrize("name", PRESETS)
def test_preset_loads(name):
    cfg = load_config(CONFIGS / f"{name}.yaml")
    assert cfg.algo_name == "muzero"
    spec = env_spec(cfg.env)
    algo = MuZero(spec, cfg.algo, seed=0)
    algo.validate()
    assert cfg.replay.overlap >= 0 and cfg.algo.unroll_steps == 5
    if name == "muzero_reanalyze_cartpole":
        assert (cfg.algo.td_steps, cfg.algo.value_loss_weight, cfg.reanalyze.num) == (5, 0.25, 1)
    if name == "muzero_tictactoe":
        assert cfg.algo.search.discount == 1.0 and spec.players == 2


def test_paper_atari_network_shapes():
    """96x96 frames are downsampled to 6x6 hidden planes (paper Appendix F)."""
    cfg = load_config(CONFIGS / "muzero_atari.yaml", ["algo.conv_channels=16", "algo.conv_blocks=1"]).algo
    net = ConvNet((96, 96, 4), 6, cfg.conv_channels, cfg.conv_blocks, 2, [16], 601, 601)
    with torch.no_grad():
        s, logits, value = net.initial_inference(torch.randint(0, 255, (2, 96, 96, 4), dtype=torch.uint8))
        s2, r, _, _ = net.recurrent_inference(s, torch.tensor([0, 5]))
    assert s.shape == (2, 16, 6, 6) and logits.shape == (2, 6) and value.shape == (2, 601)
    assert float(s.min()) >= 0.0 and float(s.max()) <= 1.0  # scaled hidden state
    assert s2.shape == s.shape and r.shape == (2, 601)


def test_atari_preset_smoke_on_pong():
    cfg = load_config(CONFIGS / "muzero_atari.yaml", [
        "algo.conv_channels=8", "algo.conv_blocks=1", "algo.hidden=[16]", "algo.search.num_simulations=2",
        "algo.value_support=20", "algo.reward_support=5", "env.screen_size=48"])
    spec = env_spec(cfg.env)
    assert spec.obs_kind == "image"
    algo = MuZero(spec, cfg.algo, seed=0)
    loop = InProcessLoop(algo, cfg.env, num_envs=2, seq_len=cfg.replay.seq_len, overlap=cfg.replay.overlap)
    loop.collect(30)
    assert loop.env_steps == 60 and loop.sequences
    metrics = loop.train(2, 4)
    assert all(np.isfinite(m["loss"]) for m in metrics)
