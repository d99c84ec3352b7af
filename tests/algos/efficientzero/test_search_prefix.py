"""The MuZero searcher with EfficientZero's LSTM value prefix: a real search equals the
plain-Python reference's visits and values, and the LSTM restarts exactly where the parent's
depth is a multiple of the horizon."""
import numpy as np
import pytest
import torch

from tests.algos.efficientzero.common import small_algo
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.searcher import Searcher
from wmdist.nets.support import support_to_scalar
from wmdist.search.api import SearchConfig
from wmdist.search.noise import sample_root_noise
from wmdist.search.reference import reference_search

torch.set_num_threads(1)


def _trained_net(horizon: int):
    algo = small_algo(search=SearchConfig(num_simulations=1, lstm_horizon=horizon), reward_support=4)
    net = algo.make_policy().net
    with torch.no_grad():  # non-trivial heads (the zero-initialised outputs would give flat numbers)
        for p in net.parameters():
            p.add_(0.3 * torch.randn_like(p))
    return algo, net.eval()


class ReferenceStep:
    """One-root model for `reference_search`: latent = (s, h, c) rows; records resets and the
    depth of each call's parent (the depth is tracked beside the latent)."""

    def __init__(self, net, cfg):
        self.net, self.cfg = net, cfg
        self.zero_state_calls = 0

    @torch.no_grad()
    def __call__(self, latent, action, reset):
        s, h, c = (torch.as_tensor(np.asarray(x))[None] for x in latent)
        if reset:
            h, c = torch.zeros_like(h), torch.zeros_like(c)
        self.zero_state_calls += int(not h.any() and not c.any())
        nxt, (h2, c2), pl, p, v = self.net.recurrent_inference_prefix(s, torch.tensor([action]), (h, c))
        prefix = float(support_to_scalar(pl.float(), self.cfg.reward_support).numpy()[0])
        value = float(support_to_scalar(v.float(), self.cfg.value_support).numpy()[0])
        return prefix, value, p.float().numpy()[0], (nxt[0].numpy(), h2[0].numpy(), c2[0].numpy())


@pytest.mark.parametrize("seed,horizon,sims", [(0, 1, 20), (1, 2, 30), (2, 3, 40), (3, 5, 120)])
def test_value_prefix_search_equals_the_reference(seed, horizon, sims):
    algo, net = _trained_net(horizon)
    cfg = algo.config
    search_cfg = SearchConfig(num_simulations=sims, value_prefix=True, lstm_horizon=horizon, discount=0.97,
                              c1=0.1)  # a small c1 lets the values steer: deep paths cross resets
    obs = np.random.default_rng(seed).normal(size=(1, 3)).astype(np.float32)
    legal = np.ones((1, 3), bool)

    zero_calls = []
    real = net.recurrent_inference_prefix

    def spy(s, a, state):  # the engine's calls: was the LSTM state zero?
        zero_calls.append(int(not state[0].any() and not state[1].any()))
        return real(s, a, state)

    net.recurrent_inference_prefix = spy
    searcher = Searcher(net, search_cfg, cfg.value_support, cfg.reward_support, False, torch.device("cpu"))
    out = searcher.run(obs, legal, None, np.random.default_rng(seed), add_noise=True)
    net.recurrent_inference_prefix = real

    with torch.no_grad():
        s0, p0, v0 = net.initial_inference(torch.as_tensor(obs))
    root_value = support_to_scalar(v0.float(), cfg.value_support).numpy()
    h0, c0 = net.initial_state(1)
    step = ReferenceStep(net, cfg)
    dirichlet, gumbel = sample_root_noise(np.random.default_rng(seed), legal, search_cfg.dirichlet_alpha,
                                          False, True)
    ref = reference_search((s0[0].numpy(), h0[0].numpy(), c0[0].numpy()), p0.float().numpy()[0],
                           float(root_value[0]), legal[0], step, search_cfg, dirichlet[0], gumbel[0], True)
    assert out.visit_counts[0].tolist() == ref.visit_counts
    assert out.root_value[0] == np.float32(ref.root_value)
    # the engine zeroes the state exactly where the reference resets (depth % horizon == 0)
    assert sum(zero_calls) == step.zero_state_calls
    # resets below the root's children happened (deep enough), and some calls continued a segment
    assert sum(zero_calls) > np.count_nonzero(out.visit_counts)
    if horizon > 1:
        assert sum(zero_calls) < sims


def test_searcher_refuses_value_prefix_without_an_lstm():
    algo = small_algo(value_prefix=False)
    net = algo.make_policy().net
    with pytest.raises(ValueError, match="value-prefix head"):
        Searcher(net, SearchConfig(value_prefix=True), 5, 3, False, torch.device("cpu"))


def test_policy_acts_with_the_value_prefix_in_the_tree():
    algo = small_algo(search=SearchConfig(num_simulations=12, lstm_horizon=2))
    assert algo.config.search.value_prefix  # the switch turns on the search's prefix backup
    pol = algo.make_policy()
    actions, extras = pol.act(np.zeros((4, 3), np.float32), np.ones(4, bool), None, None, True)
    assert actions.shape == (4,) and np.allclose(extras["search_policy"].sum(1), 1.0)


def test_muzero_with_value_prefix_is_a_config_error():
    with pytest.raises(ValueError, match="value-prefix head"):
        MuZeroConfig(search=SearchConfig(value_prefix=True)).validate()
