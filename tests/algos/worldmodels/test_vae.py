"""V's loss terms on a golden batch: numbers worked out by hand."""
import math

import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels.vae import ConvVAE, vae_loss, vae_terms


def test_kl_and_reconstruction_on_a_golden_batch():
    mu = torch.tensor([[0.5, -1.0], [0.0, 0.0]])
    logvar = torch.tensor([[0.0, math.log(2.0)], [0.0, 0.0]])
    obs = torch.zeros(2, 2, 2, 1, dtype=torch.uint8)
    obs[0, 0, 0, 0], obs[1, 1, 1, 0] = 255, 51  # x = 1.0 and 0.2
    recon = torch.full((2, 2, 2, 1), 0.5)
    rec, kl = vae_terms(mu, logvar, recon, obs)
    # frame 0: (1 - .5)^2 + 3 * .5^2 = 1.0; frame 1: (.2 - .5)^2 + 3 * .25 = 0.84
    assert rec.tolist() == pytest.approx([1.0, 0.84], rel=1e-6)
    # 0.5 * [(.25 + 1 - 1 - 0) + (1 + 2 - 1 - ln 2)] and 0 for the standard normal
    assert kl.tolist() == pytest.approx([0.5 * (0.25 + 2.0 - math.log(2.0)), 0.0], rel=1e-6)
    # free bits: tolerance 0.5 x Z = 1 nat floors both KLs
    assert vae_loss(rec, kl, 0.5, 2).item() == pytest.approx((1.0 + 1.0 + 0.84 + 1.0) / 2, rel=1e-6)
    assert vae_loss(rec, kl, 0.0, 2).item() == pytest.approx((1.0 + 0.84 + 0.5 * (2.25 - math.log(2.0))) / 2, rel=1e-6)


def test_shapes_and_a_few_steps_fit_a_frame():
    torch.manual_seed(0)
    vae = ConvVAE(3, z_dim=32, depth=8)
    obs = torch.zeros(4, 64, 64, 3, dtype=torch.uint8)
    for i in range(4):  # a bright square in a different place per frame
        obs[i, 8 * i: 8 * i + 24, 10:40] = 220
    mu, logvar = vae.encode(obs)
    assert mu.shape == logvar.shape == (4, 32)
    assert vae.decode(mu).shape == (4, 64, 64, 3)
    opt = torch.optim.Adam(vae.parameters(), 1e-3)
    losses = []
    for _ in range(15):
        mu, logvar = vae.encode(obs)
        rec, kl = vae_terms(mu, logvar, vae.decode(ConvVAE.sample(mu, logvar)), obs)
        loss = vae_loss(rec, kl, 0.5, 32)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.9 * losses[0]
