"""The EfficientZero MinAtar presets: MuZero's MinAtar settings (10x10 grid network, 16
simulations, the 100k-step / 45-minute budget) with EfficientZero's three additions on, and
each takes its first steps in tests/runtime/test_local_runner.py."""
from pathlib import Path

import pytest

from wmdist.config.loader import load_config

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

