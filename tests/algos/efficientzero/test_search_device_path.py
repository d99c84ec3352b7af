"""The searcher's accelerator path: the tree keeps host latents, so on a non-CPU device each
simulation moves the gathered latents to the network and the new ones back. The path is
forced here on the CPU (the CUDA check runs it on a GPU): it must give the host path's exact
visits and values, with MuZero's plain latent and EfficientZero's (s, h, c) tuple alike."""
import numpy as np
import pytest
import torch

from tests.algos.efficientzero.common import SPEC, small_algo
from wmdist.algos.muzero.algorithm import MuZero
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.searcher import Searcher
from wmdist.search.api import SearchConfig

torch.set_num_threads(1)


@pytest.mark.parametrize("value_prefix", [False, True])
def test_the_accelerator_path_moves_every_latent_and_changes_no_result(value_prefix):
    if value_prefix:
        algo = small_algo(search=SearchConfig(num_simulations=1, lstm_horizon=3))
    else:
        algo = MuZero(SPEC, MuZeroConfig(latent_dim=8, hidden=[16], value_support=5, reward_support=3).validate(), seed=0)
    net = algo.make_policy().net.eval()
    with torch.no_grad():  # non-trivial heads
        for p in net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=torch.Generator().manual_seed(p.numel())))
    cfg = SearchConfig(num_simulations=40, value_prefix=value_prefix, lstm_horizon=3, c1=0.5)
    obs = np.random.default_rng(0).normal(size=(4, 3)).astype(np.float32)
    legal = np.ones((4, 3), bool)
    c = algo.config

    def run(on_host: bool):
        s = Searcher(net, cfg, c.value_support, c.reward_support, False, torch.device("cpu"))
        s.on_host, s.fast = on_host, s.fast if on_host else None
        moved = {"in": 0, "out": 0}
        into, out = s._in, s._out
        s._in = lambda x: (moved.__setitem__("in", moved["in"] + 1), into(x))[1]
        s._out = lambda x: (moved.__setitem__("out", moved["out"] + 1), out(x))[1]
        return s.run(obs, legal, None, np.random.default_rng(1), add_noise=True), moved

    host, _ = run(True)
    device, moved = run(False)
    np.testing.assert_array_equal(device.visit_counts, host.visit_counts)
    np.testing.assert_array_equal(device.root_value, host.root_value)
    leaves = 3 if value_prefix else 1
    # every simulation's latent went to the network and came back (the root's came back once)
    assert moved["in"] == leaves * cfg.num_simulations
    assert moved["out"] == leaves * (cfg.num_simulations + 1)
