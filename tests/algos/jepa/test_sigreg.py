"""SIGReg (wmdist/algos/jepa/sigreg.py): the statistic against a plain loop, its size on Gaussian,
collapsed and anisotropic samples, and its gradient spreading a collapsed batch."""
from __future__ import annotations

import math

import pytest
import torch

from wmdist.algos.jepa.sigreg import effective_rank, random_directions, sigreg, trapezoid_knots


def _sigreg_loop(z: list[list[float]], dirs: list[list[float]], knots: int, t_max: float) -> float:
    """The same integral one number at a time: for each direction, the trapezoid rule over t of
    N * |phi_N(t) - exp(-t^2/2)|^2 * exp(-t^2/2), then the mean over directions."""
    n, d, m = len(z), len(z[0]), len(dirs[0])
    total = 0.0
    for j in range(m):
        x = [sum(z[i][k] * dirs[k][j] for k in range(d)) for i in range(n)]
        values = []
        for s in range(knots):
            t = t_max * s / (knots - 1)
            re = sum(math.cos(t * xi) for xi in x) / n
            im = sum(math.sin(t * xi) for xi in x) / n
            g = math.exp(-t * t / 2)
            values.append(n * ((re - g) ** 2 + im ** 2) * g)
        dt = t_max / (knots - 1)
        total += dt * (sum(values) - 0.5 * (values[0] + values[-1]))
    return total / m


def test_sigreg_matches_a_plain_loop_on_fixed_numbers():
    z = [[0.3, -1.2, 0.5], [1.1, 0.4, -0.7], [-0.2, 0.9, 2.0], [0.0, -0.5, -1.5], [2.2, 0.1, 0.3]]
    dirs = [[1.0, 0.0, 0.6], [0.0, 1.0, 0.0], [0.0, 0.0, 0.8]]  # columns are unit vectors
    for knots, t_max in ((17, 3.0), (5, 2.0)):
        want = _sigreg_loop(z, dirs, knots, t_max)
        got = float(sigreg(torch.tensor(z, dtype=torch.float64), torch.tensor(dirs, dtype=torch.float64), knots, t_max))
        assert got == pytest.approx(want, rel=1e-10)
    assert want > 0


def test_trapezoid_weights_integrate_exactly_a_linear_function():
    t, w = trapezoid_knots(17, 3.0)
    assert float((w * (2 * t + 1)).sum()) == pytest.approx(9.0 + 3.0, rel=1e-6)


def test_near_zero_for_gaussian_large_for_collapsed_and_anisotropic():
    g = torch.Generator().manual_seed(0)
    n, d = 1024, 16
    dirs = random_directions(d, 256, g)
    gaussian = float(sigreg(torch.randn((n, d), generator=g), dirs))
    collapsed = float(sigreg(torch.ones(n, d) * 0.3 + 1e-3 * torch.randn((n, d), generator=g), dirs))
    scale = torch.ones(d)
    scale[: d // 2] = 0.1  # half the dimensions nearly flat
    anisotropic = float(sigreg(torch.randn((n, d), generator=g) * scale, dirs))
    shifted = float(sigreg(torch.randn((n, d), generator=g) + 1.0, dirs))
    assert gaussian < 1.0  # O(1) under the null; the others grow like N
    assert collapsed > 100 * gaussian and collapsed > 50
    assert anisotropic > 20 * gaussian
    assert shifted > 20 * gaussian


def test_its_gradient_spreads_a_collapsed_batch():
    g = torch.Generator().manual_seed(1)
    z = (0.01 * torch.randn((256, 8), generator=g)).requires_grad_()
    opt = torch.optim.Adam([z], lr=0.05)
    rank0 = effective_rank(z.detach())
    start = float(sigreg(z.detach(), random_directions(8, 64, g)))
    for _ in range(150):
        loss = sigreg(z, random_directions(8, 64, g))  # fresh directions each step, as the learner draws them
        opt.zero_grad()
        loss.backward()
        opt.step()
    end = float(sigreg(z.detach(), random_directions(8, 64, g)))
    std = z.detach().std(0)
    assert end < start / 20
    assert float(std.min()) > 0.5 and float(std.max()) < 1.5  # every dimension spread to about unit scale
    assert effective_rank(z.detach()) > 7.0 and rank0 > 7.0  # isotropic before (tiny) and after (unit)


def test_effective_rank():
    g = torch.Generator().manual_seed(2)
    assert effective_rank(torch.randn((2000, 10), generator=g)) == pytest.approx(10, abs=0.3)
    line = torch.randn((500, 1), generator=g) * torch.arange(1.0, 6.0)  # every row on one line
    assert effective_rank(line) == pytest.approx(1.0, abs=1e-6)
    assert effective_rank(torch.ones(50, 4)) == 0.0
