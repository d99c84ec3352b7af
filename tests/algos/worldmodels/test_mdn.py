"""M's mixture density: the log-likelihood against a plain loop, and sampling at temperature tau
against the tempered mixture's analytic moments."""
import math

import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels.mdn import MDNRNN, mdn_log_prob, mdn_sample, tempered


def test_log_likelihood_matches_a_plain_loop():
    log_pi = torch.log_softmax(torch.tensor([[[0.2, -1.0, 0.5], [1.5, 0.0, -0.3]]]), -1)  # [1, Z=2, K=3]
    mu = torch.tensor([[[0.0, 1.0, -2.0], [0.5, -0.5, 3.0]]])
    log_sigma = torch.tensor([[[0.0, -0.5, 0.3], [-1.0, 0.2, 0.0]]])
    target = torch.tensor([[0.7, -0.1]])
    got = mdn_log_prob(log_pi, mu, log_sigma, target)  # [1, 2]
    for d in range(2):
        total = 0.0
        for k in range(3):
            pi, m, s, x = math.exp(log_pi[0, d, k]), float(mu[0, d, k]), math.exp(log_sigma[0, d, k]), float(target[0, d])
            total += pi * math.exp(-0.5 * ((x - m) / s) ** 2) / (s * math.sqrt(2 * math.pi))
        assert got[0, d].item() == pytest.approx(math.log(total), rel=1e-6)


def _moments(log_pi, mu, log_sigma, tau):
    """Mean and variance of the mixture tempered by tau (weights softmax(log pi / tau), sigma^2 * tau)."""
    w = torch.softmax(log_pi / tau, -1)
    var_k = torch.exp(2 * log_sigma) * tau
    mean = (w * mu).sum(-1)
    return mean, (w * (var_k + mu**2)).sum(-1) - mean**2


@pytest.mark.parametrize("tau", [0.5, 1.0, 1.5])
def test_sampling_at_temperature_matches_the_mixture_moments(tau):
    log_pi = torch.log_softmax(torch.tensor([[0.0, 1.0, -1.0], [2.0, 0.0, 0.5]]), -1)  # [Z=2, K=3]
    mu = torch.tensor([[-2.0, 1.0, 4.0], [0.0, -3.0, 2.0]])
    log_sigma = torch.log(torch.tensor([[0.5, 1.0, 0.3], [0.2, 0.8, 1.5]]))
    n = 200_000
    gen = torch.Generator().manual_seed(0)
    x = mdn_sample(log_pi.expand(n, -1, -1), mu.expand(n, -1, -1), log_sigma.expand(n, -1, -1), tau, gen)  # [n, 2]
    mean, var = _moments(log_pi, mu, log_sigma, tau)
    se_mean = torch.sqrt(var / n)
    assert torch.all((x.mean(0) - mean).abs() < 4 * se_mean), (x.mean(0), mean)
    assert torch.all((x.var(0) / var - 1).abs() < 0.02), (x.var(0), var)
    for wrong in (tau * 0.8, tau * 1.25):  # the test can tell: another tau's moments are far outside
        m_w, v_w = _moments(log_pi, mu, log_sigma, wrong)
        assert torch.any((x.mean(0) - m_w).abs() > 4 * se_mean) or torch.any((x.var(0) / v_w - 1).abs() > 0.02)


def test_tau_must_be_positive_and_one_is_the_model():
    log_pi, log_sigma = torch.log_softmax(torch.randn(4, 5), -1), torch.randn(4, 5)
    same_pi, same_s = tempered(log_pi, log_sigma, 1.0)
    assert torch.allclose(same_pi, log_pi) and torch.allclose(same_s, log_sigma)
    with pytest.raises(ValueError, match="tau must be > 0"):
        tempered(log_pi, log_sigma, 0.0)


def test_rnn_shapes_and_step_agrees_with_the_sequence():
    torch.manual_seed(0)
    rnn = MDNRNN(z_dim=4, action_dim=3, hidden=16, mixtures=5)
    z, a = torch.randn(2, 6, 4), torch.randn(2, 6, 3)
    log_pi, mu, log_s, done, _ = rnn(z, a)
    assert log_pi.shape == mu.shape == log_s.shape == (2, 6, 4, 5) and done.shape == (2, 6)
    assert torch.allclose(log_pi.exp().sum(-1), torch.ones(2, 6, 4), atol=1e-6)
    state = rnn.initial(2)
    for t in range(6):
        lp, m, _, d, state = rnn.step(z[:, t], a[:, t], state)
    assert torch.allclose(m, mu[:, -1], atol=1e-5) and torch.allclose(d, done[:, -1], atol=1e-5)
