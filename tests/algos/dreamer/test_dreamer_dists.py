"""symlog/symexp, two-hot golden values, unimix and straight-through gradients."""
import math

import pytest
import torch

from wmdist.algos.dreamer.layers import _DENSE_ROWS, Latent, SplitLinear
from wmdist.nets.dists import (
    sample_index_from_probs, straight_through_onehot, symexp, symlog, twohot_bins, twohot_encode, twohot_loss,
    twohot_mean, twohot_nll, unimix_logits,
)


def test_symlog_symexp_round_trip_and_values():
    x = torch.tensor([-1e6, -20.0, -1.0, -1e-4, 0.0, 1e-4, 1.0, 3.0, 1e6], dtype=torch.float64)
    torch.testing.assert_close(symexp(symlog(x)), x, rtol=1e-9, atol=1e-12)
    torch.testing.assert_close(symlog(torch.tensor([0.0, 1.0, -1.0])), torch.tensor([0.0, 0.6931472, -0.6931472]))


def test_twohot_golden_values():
    bins = torch.tensor([-2.0, -1.0, 0.0, 1.0, 2.0])
    enc = twohot_encode(torch.tensor([0.0, 0.3, -1.75, 1.0, 5.0, -9.0]), bins)
    expected = torch.tensor([
        [0, 0, 1.0, 0, 0],
        [0, 0, 0.7, 0.3, 0],
        [0.75, 0.25, 0, 0, 0],
        [0, 0, 0, 1.0, 0],
        [0, 0, 0, 0, 1.0],  # outside the support: all mass on the end bin
        [1.0, 0, 0, 0, 0],
    ])
    torch.testing.assert_close(enc, expected)


def test_twohot_v3_support_recovers_value_and_loss():
    bins = twohot_bins(255, -20, 20)
    assert bins.shape == (255,) and bins[127] == 0.0
    y = torch.tensor([0.0, 1.0, -7.5, 123.0, 3000.0])
    target = twohot_encode(symlog(y), bins)
    torch.testing.assert_close(target.sum(-1), torch.ones(5))
    assert (target > 0).sum(-1).le(2).all()
    # logits that put exactly the two-hot mass recover y through the mean
    logits = torch.log(target.clamp_min(1e-30))
    torch.testing.assert_close(twohot_mean(logits, bins), y, rtol=1e-4, atol=1e-4)
    # cross-entropy with uniform logits is log(255)
    loss = twohot_loss(torch.zeros(5, 255), y, bins)
    torch.testing.assert_close(loss, torch.full((5,), float(torch.log(torch.tensor(255.0)))))


def test_unimix_floor_and_sampler_frequencies():
    logp = unimix_logits(torch.tensor([[100.0, 0.0, 0.0, 0.0]]), 0.01)
    probs = logp.exp()[0]
    torch.testing.assert_close(probs, torch.tensor([0.9925, 0.0025, 0.0025, 0.0025]))
    g = torch.Generator().manual_seed(0)
    p = torch.tensor([0.1, 0.2, 0.3, 0.4]).expand(200_000, 4)
    idx = sample_index_from_probs(p, g)
    freq = torch.bincount(idx, minlength=4).float() / 200_000
    torch.testing.assert_close(freq, torch.tensor([0.1, 0.2, 0.3, 0.4]), atol=5e-3, rtol=0)


def test_straight_through_gradient_is_identity_to_probs():
    probs = torch.softmax(torch.randn(3, 5), -1).requires_grad_(True)
    idx = torch.tensor([0, 4, 2])
    st = straight_through_onehot(idx, probs)
    torch.testing.assert_close(st.detach(), torch.nn.functional.one_hot(idx, 5).float())
    w = torch.randn(3, 5)
    (st * w).sum().backward()
    torch.testing.assert_close(probs.grad, w)  # d(onehot + p - sg(p))/dp = 1


@pytest.mark.parametrize("n", [7, 200])  # below and above layers._DENSE_ROWS: both code paths
def test_embedding_bag_linear_matches_dense_values_and_gradients(n):
    assert (n <= _DENSE_ROWS) == (n == 7)
    torch.manual_seed(0)
    s, c, d = 4, 3, 5
    lin = SplitLinear({"h": 6, "z": s * c}, d)
    probs = torch.softmax(torch.randn(n, s, c), -1).requires_grad_(True)
    idx = torch.randint(0, c, (n, s))
    h = torch.randn(n, 6)
    lat = Latent(index=idx, probs=probs, classes=c)
    g = torch.randn(n, d)
    out_fast = lin({"h": h, "z": lat})
    (out_fast * g).sum().backward()
    grads_fast = [probs.grad.clone()] + [p.grad.clone() for p in lin.parameters()]
    probs.grad = None
    lin.zero_grad()
    out_dense = lin({"h": h, "z": lat.dense()})
    (out_dense * g).sum().backward()
    grads_dense = [probs.grad] + [p.grad for p in lin.parameters()]
    torch.testing.assert_close(out_fast, out_dense)
    for a, b in zip(grads_fast, grads_dense):
        torch.testing.assert_close(a, b)
    assert probs.grad.abs().sum() > 0


@pytest.mark.parametrize("grad", [True, False])  # the custom autograd path and the plain embedding bag
def test_embedding_bag_linear_under_bf16_autocast_matches_dense_and_stays_bf16(grad):
    """Under autocast the one-hot rows are summed in bf16 like the dense matmul there (a
    mixed bf16 + fp32 sum would promote to fp32 on a slow path); weight gradients are
    accumulated in fp32 and match the dense layer's; the straight-through gradient to the
    (fp32) probabilities is computed in bf16, as autocast computes the dense matmul's, and
    arrives in fp32."""
    torch.manual_seed(0)
    n, s, c, d = 300, 8, 16, 24
    lin = SplitLinear({"h": 6, "z": s * c}, d)
    probs = torch.softmax(torch.randn(n, s, c), -1).requires_grad_(grad)
    lat = Latent(index=torch.randint(0, c, (n, s)), probs=probs if grad else None, classes=c)
    h = torch.randn(n, 6)
    g = torch.randn(n, d)

    def run(z):
        lin.zero_grad()
        probs.grad = None
        with torch.autocast("cpu", dtype=torch.bfloat16), torch.set_grad_enabled(grad):
            out = lin({"h": h, "z": z})
        if grad:
            (out.float() * g).sum().backward()
        return out, [None if p.grad is None else p.grad.clone() for p in [probs, *lin.parameters()]]

    out_fast, grads_fast = run(lat)
    out_dense, grads_dense = run(lat.dense())
    assert out_fast.dtype == out_dense.dtype == torch.bfloat16
    torch.testing.assert_close(out_fast.float(), out_dense.float(), atol=0.05, rtol=0.02)
    if grad:
        for a, b in zip(grads_fast, grads_dense):
            assert a.dtype == torch.float32
            torch.testing.assert_close(a, b, atol=0.05, rtol=0.02)
        # the same bf16 products as the dense path (an fp32 grad @ W^T differs from it by ~3e-3 here)
        assert (grads_fast[0] - grads_dense[0]).abs().max() < 1e-3


def test_twohot_gather_loss_and_mean_match_the_dense_reference():
    """The optimised two-hot loss (two gathered bins) and mean (a mat-vec) against the plain
    dense formulas, values and gradients, including targets outside the support."""
    torch.manual_seed(0)
    bins = twohot_bins(255, -20, 20)
    logits = torch.randn(6, 9, 255, requires_grad=True)
    y = torch.cat([torch.randn(6, 8) * 50, torch.tensor([1e12, -1e12, 0.0, 3.0, -2.5, 1e9]).unsqueeze(-1)], -1)
    fast = twohot_loss(logits, y, bins)
    (g_fast,) = torch.autograd.grad((fast * torch.arange(9.0)).sum(), logits)
    dense = -(twohot_encode(symlog(y), bins) * torch.log_softmax(logits, -1)).sum(-1)
    (g_dense,) = torch.autograd.grad((dense * torch.arange(9.0)).sum(), logits)
    torch.testing.assert_close(fast, dense)
    torch.testing.assert_close(g_fast, g_dense)
    logp = torch.log_softmax(logits.detach(), -1)
    torch.testing.assert_close(twohot_nll(logp, y, bins), dense.detach())
    mean_ref = symexp((torch.softmax(logits.detach(), -1) * bins).sum(-1))
    torch.testing.assert_close(twohot_mean(logits.detach(), bins), mean_ref, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("init_std", [5.0, 1.0, 0.3])
def test_tanh_normal_actor_starts_at_its_init_std_and_its_log_prob_matches_sampling(init_std):
    from wmdist.algos.dreamer.actor import ActionDist

    out = torch.zeros(4000, 2)  # [N, 2A], A = 1: what a fresh head outputs
    d = ActionDist(out, False, "tanh_normal", 0.0, 0.1, 1.0, init_std)
    torch.testing.assert_close(d.std, torch.full((4000, 1), init_std + 0.1))
    a = d.sample(torch.Generator().manual_seed(0))  # [N, 1] in (-1, 1)
    # the empirical spread of atanh(a) is the pre-tanh std
    assert abs(float(torch.atanh(a.clamp(-0.999999, 0.999999)).std()) - (init_std + 0.1)) < 0.15 * (init_std + 0.1)
    # the density of tanh(x), x ~ N(0, s), over [-0.999, 0.999] holds P(|x| < atanh 0.999)
    grid = torch.linspace(-0.999, 0.999, 20001).unsqueeze(-1)  # [G, 1]
    g = ActionDist(torch.zeros(len(grid), 2), False, "tanh_normal", 0.0, 0.1, 1.0, init_std)
    mass = float(torch.trapezoid(g.log_prob(grid).exp(), grid.squeeze(-1)))
    expected = math.erf(math.atanh(0.999) / ((init_std + 0.1) * math.sqrt(2)))
    assert abs(mass - expected) < 0.01
