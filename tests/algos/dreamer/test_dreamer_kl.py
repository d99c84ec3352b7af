"""KL routing (dyn -> prior, rep -> posterior), balancing split, and the free-bits clamp."""
import pytest
import torch

from wmdist.algos.dreamer import DreamerConfig
from wmdist.algos.dreamer.kl import kl_loss
from wmdist.algos.dreamer.rssm import RSSM
from wmdist.nets.dists import categorical_kl, unimix_logits


def _logits(seed):
    g = torch.Generator().manual_seed(seed)
    post = unimix_logits(torch.randn(2, 3, 4, 5, generator=g) * 2, 0.01).requires_grad_(True)  # [B, T, S, C]
    prior = unimix_logits(torch.randn(2, 3, 4, 5, generator=g) * 2, 0.01).requires_grad_(True)
    return post, prior


def _grads(dyn, rep, free=0.0, free_avg=False):
    post, prior = _logits(0)
    loss, _, _ = kl_loss(categorical_kl, post, prior, torch.ones(2, 3), dyn, rep, free, free_avg)
    loss.backward()
    return post.grad, prior.grad


def test_dyn_term_trains_only_prior_and_rep_only_posterior():
    gp, gq = _grads(dyn=1.0, rep=0.0)
    assert gp.abs().sum() == 0 and gq.abs().sum() > 0
    gp, gq = _grads(dyn=0.0, rep=1.0)
    assert gp.abs().sum() > 0 and gq.abs().sum() == 0


def test_kl_balancing_splits_gradients_as_configured():
    # the full KL with gradients to both sides (Dreamer V1) ...
    post, prior = _logits(0)
    categorical_kl(post, prior).mean().backward()
    full_p, full_q = post.grad, prior.grad
    # ... V2 balancing alpha = 0.8: 80% of the gradient reaches the prior, 20% the posterior
    gp, gq = _grads(dyn=0.8, rep=0.2)
    torch.testing.assert_close(gq, 0.8 * full_q)
    torch.testing.assert_close(gp, 0.2 * full_p)


def test_free_bits_clamp_per_step_and_per_batch_mean():
    post, prior = _logits(0)
    kl = categorical_kl(post, prior).detach()  # [B, T]
    free = float(kl.median())
    loss, dyn, _ = kl_loss(categorical_kl, post, prior, torch.ones(2, 3), 0.5, 0.1, free, free_avg=False)
    expected = 0.6 * torch.clamp(kl, min=free).mean()
    torch.testing.assert_close(loss, expected)
    torch.testing.assert_close(dyn, kl.mean())
    loss.backward()
    below = kl < free  # steps under the floor get no gradient at all
    assert post.grad[below].abs().sum() == 0 and prior.grad[below].abs().sum() == 0
    assert post.grad[~below].abs().sum() > 0
    # V1 free nats on the batch mean: everything clamped -> no gradient
    post, prior = _logits(0)
    loss, _, _ = kl_loss(categorical_kl, post, prior, torch.ones(2, 3), 1.0, 1.0, float(kl.mean()) + 1, free_avg=True)
    loss.backward()
    assert post.grad.abs().sum() == 0 and prior.grad.abs().sum() == 0
    assert float(loss.detach()) == pytest.approx(2 * (float(kl.mean()) + 1))


@pytest.mark.parametrize("classes", [32, 0])
def test_rssm_routing_on_modules(classes):
    """Through the real RSSM (one step): dyn reaches only the prior net, rep only the posterior side."""
    cfg = DreamerConfig(version=3 if classes else 1, deter=16, units=16, stoch=4 if not classes else 4, classes=classes).resolved()
    rssm = RSSM(cfg, embed_dim=8, action_dim=2)
    embed = torch.randn(3, 1, 8, requires_grad=True)
    out = rssm.observe(embed, torch.zeros(3, 1, 2), torch.ones(3, 1, dtype=torch.bool))
    prior_params = list(rssm.prior_net.parameters())
    post_params = list(rssm.post_in.parameters()) + list(rssm.post_out.parameters())
    for dyn, rep, trained, untouched in ((1.0, 0.0, prior_params, post_params), (0.0, 1.0, post_params, prior_params)):
        rssm.zero_grad(set_to_none=True)
        loss, _, _ = kl_loss(rssm.kl, out.post, out.prior, torch.ones(3, 1), dyn, rep, 0.0, False)
        loss.backward(retain_graph=True)
        assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in trained)
        assert all(p.grad is None or p.grad.abs().sum() == 0 for p in untouched)
