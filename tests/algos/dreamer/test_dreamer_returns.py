"""Lambda-returns against an n-step-mixture reference, and the percentile normaliser."""
import numpy as np
import pytest
import torch

from wmdist.algos.dreamer.returns import PercentileNormalizer, lambda_returns


def reference_lambda_returns(r, c, v, lam):
    """Plain-loop definition: R^lambda_t = (1 - lam) sum_n lam^(n-1) G^n_t + lam^(H-t-1) G^(H-t)_t,
    with n-step returns G^n_t = sum_{k<n} (prod_{j<=k} c_{t+j}) r_{t+k} + (prod_{j<n} c_{t+j}) v_{t+n}."""
    H, N = r.shape
    out = np.zeros((H, N))
    for i in range(N):
        for t in range(H):
            def g(n):
                total, disc = 0.0, 1.0
                for k in range(n):
                    total += disc * r[t + k, i]
                    disc *= c[t + k, i]
                return total + disc * v[t + n, i]
            steps = H - t
            acc = sum((1 - lam) * lam ** (n - 1) * g(n) for n in range(1, steps))
            out[t, i] = acc + lam ** (steps - 1) * g(steps)
    return out


@pytest.mark.parametrize("lam", [0.0, 0.95, 1.0])
def test_lambda_returns_match_reference(lam):
    rng = np.random.default_rng(0)
    H, N = 6, 3
    r = rng.normal(size=(H, N))
    c = 0.99 * rng.uniform(0.5, 1.0, size=(H, N))
    c[3, 1] = 0.0  # a predicted episode end
    v = rng.normal(size=(H + 1, N))
    ours = lambda_returns(torch.tensor(r), torch.tensor(c), torch.tensor(v), lam).numpy()
    np.testing.assert_allclose(ours, reference_lambda_returns(r, c, v, lam), rtol=1e-10, atol=1e-10)


def test_lambda_returns_shape_error():
    with pytest.raises(ValueError, match="line up"):
        lambda_returns(torch.zeros(3, 2), torch.zeros(3, 2), torch.zeros(3, 2), 0.95)


def test_percentile_normaliser_tracks_ema_of_quantiles():
    norm = PercentileNormalizer(decay=0.99, low=0.05, high=0.95)
    rng = np.random.default_rng(1)
    lo = hi = 0.0
    for _ in range(50):
        x = rng.normal(5.0, 20.0, size=1000)
        norm.update(torch.tensor(x, dtype=torch.float32))
        lo = 0.99 * lo + 0.01 * np.quantile(x, 0.05)
        hi = 0.99 * hi + 0.01 * np.quantile(x, 0.95)
    assert float(norm.low) == pytest.approx(lo, rel=1e-4)
    assert float(norm.high) == pytest.approx(hi, rel=1e-4)
    assert norm.scale == pytest.approx(max(1.0, hi - lo), rel=1e-4)


def test_percentile_normaliser_never_scales_small_returns_up():
    norm = PercentileNormalizer()
    for _ in range(500):
        norm.update(torch.rand(100) * 0.1)  # spread 0.1 < 1
    assert norm.scale == 1.0
