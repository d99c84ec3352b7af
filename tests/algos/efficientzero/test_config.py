"""Bad EfficientZero input is one ConfigError line before anything starts; the switches make
the same algorithm MuZero Reanalyze."""
from pathlib import Path

import pytest

from wmdist.config.errors import ConfigError
from wmdist.config.loader import load_config
from wmdist.runtime.preflight import check_env_and_algo

CONFIGS = Path(__file__).parents[3] / "configs"


def _one_line(err: pytest.ExceptionInfo) -> str:
    msg = str(err.value)
    assert "\n" not in msg
    return msg


def test_value_prefix_on_a_network_without_one_is_a_config_error():
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS / "muzero_cartpole.yaml", ["algo.search.value_prefix=true"])
    assert "value-prefix" in _one_line(err)
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS / "efficientzero_cartpole.yaml", ["algo.value_prefix=false", "algo.search.value_prefix=true"])
    assert "value-prefix" in _one_line(err)


def test_off_policy_correction_without_reanalyzers_is_a_config_error():
    cfg = load_config(CONFIGS / "efficientzero_cartpole.yaml", ["reanalyze.num=0"])
    with pytest.raises(ConfigError) as err:
        check_env_and_algo(cfg)
    assert "reanalyze.num" in _one_line(err)


def test_every_addition_switched_off_is_muzero_reanalyze():
    off = ["algo.value_prefix=false", "algo.consistency_weight=0", "algo.off_policy_correction=false"]
    cfg = load_config(CONFIGS / "efficientzero_cartpole.yaml", off)
    _, algo = check_env_and_algo(cfg)
    assert not cfg.algo.search.value_prefix
    assert set(algo.extra_fields()) == {"search_policy", "search_value"}  # MuZero's stored extras
    net = algo.make_learner().net
    assert net.prefix is None and net.consistency is None and net.base.reward_head is not None
    cfg_on = load_config(CONFIGS / "efficientzero_cartpole.yaml")
    assert cfg_on.algo.search.value_prefix and cfg_on.algo.search.lstm_horizon == 5


def test_value_prefix_on_a_two_player_game_is_a_config_error():
    cfg = load_config(CONFIGS / "muzero_tictactoe.yaml", ["algo.name=efficientzero", "reanalyze.num=1",
                                                          "algo.augment_symmetries=false"])
    with pytest.raises(ConfigError) as err:
        check_env_and_algo(cfg)
    assert "two players" in _one_line(err)
