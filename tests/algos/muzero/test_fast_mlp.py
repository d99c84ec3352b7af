"""The MLP network's fast self-play inference is bit-identical to the module path: one
recurrent call, and whole searches (visit counts, targets, root values) with loaded weights."""
import numpy as np
import torch

from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.algos.muzero.fast_mlp import FastMLPInference
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec
from wmdist.search.api import SearchConfig


def _policy(seed: int = 0):
    cfg = MuZeroConfig(search=SearchConfig(num_simulations=12), latent_dim=32, hidden=[64],
                       value_support=25, reward_support=5)
    spec = env_spec(EnvConfig(id="gym:CartPole-v1"))
    pol = MuZero(spec, cfg, seed).make_policy()
    with torch.no_grad():  # the zero-initialised heads would make every output trivially equal
        g = torch.Generator().manual_seed(seed)
        for p in pol.net.parameters():
            p.copy_(torch.randn(p.shape, generator=g) * 0.5)
    return pol


def test_recurrent_call_is_bit_identical_to_the_module_path():
    searcher = _policy().searcher
    assert searcher.fast is not None
    rng = np.random.default_rng(0)
    latents = torch.rand(32, 32)
    actions = rng.integers(0, 2, 32)
    fast = searcher._recurrent(latents, actions)
    fast_path, searcher.fast = searcher.fast, None
    slow = searcher._recurrent(latents, actions)
    searcher.fast = fast_path
    for a, b in zip(fast[:3], slow[:3]):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert torch.equal(fast[3], slow[3])


def test_whole_searches_match_and_loaded_weights_apply():
    fast_pol, slow_pol = _policy(), _policy()
    slow_pol.searcher.fast = None
    new = {k: v.detach().numpy() * 0.7 for k, v in fast_pol.net.state_dict().items()}
    for pol in (fast_pol, slow_pol):  # the fast path reads the weights at call time
        pol.set_weights(new, 1)
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(8, 4)).astype(np.float32)
    legal = np.ones((8, 2), bool)
    for seed in range(3):
        a = fast_pol.searcher.run(obs, legal, None, np.random.default_rng(seed), add_noise=True)
        b = slow_pol.searcher.run(obs, legal, None, np.random.default_rng(seed), add_noise=True)
        assert np.array_equal(a.visit_counts, b.visit_counts)
        assert np.array_equal(a.policy_target, b.policy_target) and np.array_equal(a.root_value, b.root_value)


def test_other_networks_keep_the_module_path():
    class Sub(torch.nn.Module):
        pass

    assert FastMLPInference.build(Sub(), 5, 5) is None
