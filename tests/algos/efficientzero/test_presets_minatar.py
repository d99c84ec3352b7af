"""The EfficientZero MinAtar presets: MuZero's MinAtar settings (10x10 grid network, 16
simulations, the 100k-step / 45-minute budget) with EfficientZero's three additions on, and
each runs self-play with the value-prefix search and takes learner updates in process."""
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.algos.muzero.loop import InProcessLoop
from wmdist.algos.efficientzero import EfficientZero
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec

torch.set_num_threads(1)
CONFIGS = Path(__file__).resolve().parents[3] / "configs"


@pytest.mark.parametrize("game", ["breakout", "asterix"])
def test_preset_is_the_muzero_one_plus_the_three_additions(game):
    ez = load_config(CONFIGS / f"efficientzero_minatar_{game}.yaml")
    mz = load_config(CONFIGS / f"muzero_minatar_{game}.yaml")
    assert ez.env == mz.env and (ez.run.max_env_steps, ez.run.max_minutes) == (100_000, 45)
    a = ez.algo
    assert ez.algo_name == "efficientzero" and a.value_prefix and a.search.value_prefix
    assert a.consistency_weight > 0 and a.off_policy_correction and ez.reanalyze.num >= 1
    # the network and search are MuZero's MinAtar ones
    for field in ("network", "conv_stem", "conv_channels", "conv_blocks", "value_support", "reward_support"):
        assert getattr(a, field) == getattr(mz.algo, field), field
    assert a.search.num_simulations == mz.algo.search.num_simulations


def test_breakout_self_play_and_updates():
    cfg = load_config(CONFIGS / "efficientzero_minatar_breakout.yaml")
    spec = env_spec(cfg.env)
    algo = EfficientZero(spec, cfg.algo, seed=0)
    loop = InProcessLoop(algo, cfg.env, num_envs=2, seq_len=cfg.replay.seq_len, overlap=cfg.replay.overlap)
    loop.collect(40)
    assert loop.env_steps == 80 and loop.sequences
    metrics = loop.train(3, 8)
    assert all(np.isfinite(m["loss"]) for m in metrics)
    assert all(np.isfinite(m["consistency_loss"]) for m in metrics)
