"""`wmdist dream RUN --check`'s fixed policies act as they are named, and the check refuses a
run that is not World Models or has no dream starts, in one line."""
import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels.controller import act_batched
from wmdist.algos.worldmodels.dream_check import dream_check, fixed_controllers
from wmdist.runtime.evaluate import format_check
from wmdist.envs.spec import EnvSpec

DISCRETE = EnvSpec(id="d", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image", num_actions=3)
CONTINUOUS = EnvSpec(id="c", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image", action_shape=(3,),
                     action_low=(-1.0, 0.0, 0.0), action_high=(1.0, 1.0, 1.0))


def test_fixed_controllers_ignore_the_state():
    g = torch.Generator().manual_seed(0)
    z, h = torch.randn(1, 50, 8, generator=g) * 5, torch.randn(1, 50, 16, generator=g) * 5  # [1, R, Z], [1, R, H]
    fixed = fixed_controllers(DISCRETE, 8, 16)
    assert list(fixed) == ["always action 0", "always action 1", "always action 2"]
    for i, x in enumerate(fixed.values()):
        assert (act_batched(torch.as_tensor(x)[None], z, h, DISCRETE) == i).all()
    (x,) = fixed_controllers(CONTINUOUS, 8, 16).values()
    assert (act_batched(torch.as_tensor(x)[None], z, h, CONTINUOUS) == 0).all()  # tanh(0): mid-range


def test_a_run_without_dream_starts_is_refused():
    with pytest.raises(ValueError, match="no dream starts"):
        dream_check(None, DISCRETE, {}, {"bank_mu": np.zeros((0, 8))})


def test_the_table_shows_the_dream_against_the_real_game():
    lines = format_check([{"policy": "controller", "dream": 900.0, "real": 300.0},
                          {"policy": "always action 0", "dream": 120.0, "real": 0.0}], 1.15, 64, 5)
    assert "tau 1.15" in lines[0] and lines[2].split() == ["controller", "900.0", "300.0", "3.00"]
    assert lines[3].endswith("-")  # no ratio to a zero return
