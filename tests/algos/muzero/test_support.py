"""Golden values for h, h^-1 and the two-hot support encoding (MuZero Appendix F)."""
import math

import pytest
import torch

from wmdist.nets.support import h, h_inv, scalar_to_support, support_to_scalar, two_hot


def test_h_golden_values():
    x = torch.tensor([0.0, 3.0, -3.0, 8.0, 99.0], dtype=torch.float64)
    want = [0.0, 1.003, -1.003, 2.008, 9.0 + 0.099]  # sqrt(|x|+1) - 1 + 0.001 x
    assert torch.allclose(h(x), torch.tensor(want, dtype=torch.float64), atol=1e-12)


def test_h_inverse_round_trip():
    x = torch.linspace(-5000, 5000, 2001, dtype=torch.float64)
    assert torch.allclose(h_inv(h(x)), x, atol=1e-6, rtol=1e-9)
    assert h_inv(torch.tensor(1.003, dtype=torch.float64)).item() == pytest.approx(3.0, abs=1e-9)


def test_two_hot_golden():
    enc = two_hot(torch.tensor([3.7, -3.7, 5.0, 9.0]), support=5)  # atoms -5..5
    assert enc.shape == (4, 11)
    assert enc[0, 5 + 3].item() == pytest.approx(0.3, abs=1e-6)
    assert enc[0, 5 + 4].item() == pytest.approx(0.7, abs=1e-6)
    assert enc[1, 5 - 4].item() == pytest.approx(0.7, abs=1e-6)
    assert enc[1, 5 - 3].item() == pytest.approx(0.3, abs=1e-6)
    assert enc[2, 10].item() == pytest.approx(1.0) and enc[3, 10].item() == pytest.approx(1.0)  # clipped
    assert torch.allclose(enc.sum(-1), torch.ones(4))


def test_scalar_support_round_trip():
    x = torch.tensor([0.0, 1.0, -2.5, 37.2, 300.0], dtype=torch.float64)
    probs = scalar_to_support(x, support=20)
    back = support_to_scalar(torch.log(probs.clamp_min(1e-30)), support=20)
    assert torch.allclose(back, x, atol=1e-6)
    assert math.isclose(probs[1, 20 + 0].item(), 1 - 0.415213562, rel_tol=1e-6)  # h(1) = 0.41521...


def test_bad_support_is_a_clear_error():
    with pytest.raises(ValueError, match="atoms"):
        support_to_scalar(torch.zeros(3, 7), support=5)
    with pytest.raises(ValueError, match="support"):
        two_hot(torch.zeros(2), support=0)
