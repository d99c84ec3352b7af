"""The conv network's folded search inference (`fast_conv.py`) against the module in eval mode:
one recurrent call (MinAtar's grid network and the Atari downsampling one), weights loaded
in place afterwards, whole searches, and EfficientZero's value-prefix path."""
from pathlib import Path

import numpy as np
import pytest
import torch

from wmdist.algos.efficientzero import EfficientZero
from wmdist.algos.muzero import MuZero
from wmdist.algos.muzero.fast_conv import FastConvInference
from wmdist.algos.muzero.networks import MLPNet
from wmdist.algos.muzero.networks_conv import ConvNet
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec

CONFIGS = Path(__file__).resolve().parents[3] / "configs"


def _randomise(net: torch.nn.Module, seed: int) -> None:
    """Every weight and BN statistic random: the zero-initialised heads and fresh statistics
    (mean 0, var 1) would make folding an identity and every output trivially equal."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(torch.randn(p.shape, generator=g) * 0.3)
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.copy_(torch.randn(m.running_mean.shape, generator=g) * 0.5)
                m.running_var.copy_(torch.rand(m.running_var.shape, generator=g) * 1.5 + 0.25)
                m.weight.copy_(torch.rand(m.weight.shape, generator=g) + 0.5)


def _close(fast, slow) -> None:
    """Equal up to float rounding: folding reorders sums whose terms reach the outputs' scale."""
    for a, b in zip(fast, slow):
        scale = float(b.abs().max()) + 1e-6
        assert a.shape == b.shape and float((a - b).abs().max()) <= 1e-5 * scale, (float((a - b).abs().max()), scale)


@pytest.mark.parametrize("stem, obs_shape", [("grid", (10, 10, 4)), ("atari", (24, 24, 3))])
def test_recurrent_call_matches_the_module_in_eval_mode(stem, obs_shape):
    net = ConvNet(obs_shape, 6, 16, 2, 2, [32], 41, 11, downsample_blocks=(1, 1, 1), stem=stem)
    _randomise(net, 0)
    net.eval()
    fast = FastConvInference.build(net)
    assert fast is not None
    with torch.no_grad():
        latent = net.represent(torch.randint(0, 255, (12, *obs_shape), dtype=torch.uint8))
        actions = torch.arange(12) % 6
        _close(fast.recurrent_inference(latent, actions), net.recurrent_inference(latent, actions))
        # weights written in place afterwards (as `set_weights` does): the fold follows them
        other = ConvNet(obs_shape, 6, 16, 2, 2, [32], 41, 11, downsample_blocks=(1, 1, 1), stem=stem)
        _randomise(other, 1)
        net.load_state_dict(other.state_dict())
        _close(fast.recurrent_inference(latent, actions), net.recurrent_inference(latent, actions))


def _policy(algo: type, preset: str, seed: int = 0):
    cfg = load_config(CONFIGS / preset)
    policy = algo(env_spec(cfg.env), cfg.algo, seed).make_policy()
    _randomise(policy.net, seed)
    return policy


@pytest.mark.parametrize("algo, preset", [(MuZero, "muzero_minatar_breakout.yaml"),
                                          (EfficientZero, "efficientzero_minatar_breakout.yaml")])
def test_whole_searches_match_the_module_path(algo, preset):
    """Same visits, targets and root values with the folded path and without it, on loaded
    weights (EfficientZero: the value prefix's LSTM over the folded base's features)."""
    fast_pol, slow_pol = _policy(algo, preset), _policy(algo, preset)
    assert fast_pol.searcher.conv is not None
    slow_pol.searcher.conv = None
    new = {k: v.detach().numpy() * 0.9 for k, v in fast_pol.net.state_dict().items()}
    for pol in (fast_pol, slow_pol):
        pol.set_weights(new, 1)
    rng = np.random.default_rng(0)
    obs = (rng.random((6, 10, 10, 4)) < 0.1).astype(np.uint8)
    legal = np.ones((6, 6), bool)
    for seed in range(2):
        a = fast_pol.searcher.run(obs, legal, None, np.random.default_rng(seed), add_noise=True)
        b = slow_pol.searcher.run(obs, legal, None, np.random.default_rng(seed), add_noise=True)
        assert np.array_equal(a.visit_counts, b.visit_counts)
        assert np.allclose(a.root_value, b.root_value, rtol=1e-4, atol=1e-4)


def test_other_networks_keep_the_module_path():
    class Sub(ConvNet):
        pass

    assert FastConvInference.build(MLPNet(4, 2, 8, [8], 5, 5)) is None
    assert FastConvInference.build(Sub((10, 10, 4), 6, 8, 1, 2, [8], 5, 5, stem="grid")) is None


def test_the_selfplay_bench_times_both_paths():
    from wmdist.bench.selfplay import folded_conv_vs_module

    row = folded_conv_vs_module("muzero_minatar_breakout.yaml", steps=2)
    assert row["case"] == "folded_conv_vs_module" and row["envs"] == 16 and row["simulations"] == 16
    assert row["module_env_steps_per_s"] > 0 and row["fast_env_steps_per_s"] > 0 and row["speedup_cpu_seconds"] > 0
