"""The EfficientZero MinAtar presets: MuZero's MinAtar settings (10x10 grid network, 16
simulations, the 100k-step / 45-minute budget) with EfficientZero's three additions on, and
each takes its first steps in tests/runtime/test_local_runner.py."""
from pathlib import Path

import pytest
import torch

from wmdist.algos.efficientzero.build import build_net
from wmdist.algos.muzero.build import build_net as build_muzero_net
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec

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


@pytest.mark.parametrize("game", ["breakout", "asterix"])
def test_network_is_the_muzero_presets_network(game):
    """The built network, not just the config fields: EfficientZero once ignored `conv_stem`
    and downsampled the 10x10 grid to 1x1 planes, and played Breakout at random."""
    ez = load_config(CONFIGS / f"efficientzero_minatar_{game}.yaml")
    mz = load_config(CONFIGS / f"muzero_minatar_{game}.yaml")
    spec = env_spec(ez.env)
    net, ref = build_net(spec, ez.algo), build_muzero_net(spec, mz.algo)
    obs = torch.zeros((2, *spec.obs_shape), dtype=torch.uint8)
    net.eval()
    ref.eval()
    with torch.no_grad():
        assert net.represent(obs).shape == ref.represent(obs).shape == (2, mz.algo.conv_channels, 10, 10)
    shapes = {k: tuple(v.shape) for k, v in net.base.state_dict().items()}
    ref_shapes = {k: tuple(v.shape) for k, v in ref.state_dict().items() if not k.startswith("reward_head.")}
    assert shapes == ref_shapes  # the value-prefix LSTM replaces only the reward head
