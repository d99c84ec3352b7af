"""The batched CEM planner: the known optimum of a point mass with quadratic cost (closed form
and a brute-force grid), rows that don't interact, warm starts, a fixed RNG."""
import itertools

import numpy as np
import pytest
import torch

from wmdist.search.cem import CEMConfig, cem_plan, shift_plan

H = 4  # horizon of the toy problem
R = 0.5  # action cost weight


def _positions_matrix(h: int) -> np.ndarray:
    """Double integrator v' = v + a, p' = p + v': positions p_1..p_H = p0 + v0 t + M a, M [H, H]."""
    m = np.zeros((h, h))
    for t in range(h):  # p_{t+1} = p0 + (t+1) v0 + sum_{s<=t} (t + 1 - s) a_s
        for s in range(t + 1):
            m[t, s] = t + 1 - s
    return m


M = _positions_matrix(H)


def _cost_np(actions: np.ndarray, p0: float, v0: float) -> np.ndarray:
    """Sum of p_t^2 + R a_t^2 for sequences [..., H] -> [...]."""
    base = p0 + v0 * np.arange(1, H + 1)
    p = base + actions @ M.T
    return (p ** 2).sum(-1) + R * (actions ** 2).sum(-1)


def _score_fn(p0: torch.Tensor, v0: torch.Tensor):
    """Per-row point masses: p0, v0 [E]; actions [E, J, H, 1] -> minus the cost [E, J]."""
    m = torch.as_tensor(M, dtype=torch.float32)

    def score(actions: torch.Tensor) -> torch.Tensor:
        a = actions[..., 0]  # [E, J, H]
        base = p0[:, None, None] + v0[:, None, None] * torch.arange(1, H + 1, dtype=torch.float32)  # [E, 1, H]
        p = base + a @ m.T
        return -((p ** 2).sum(-1) + R * (a ** 2).sum(-1))

    return score


def _closed_form(p0: float, v0: float) -> np.ndarray:
    """argmin ||base + M a||^2 + R ||a||^2 = -(M^T M + R I)^-1 M^T base (unconstrained)."""
    base = p0 + v0 * np.arange(1, H + 1)
    return -np.linalg.solve(M.T @ M + R * np.eye(H), M.T @ base)


def _grid_best(p0: float, v0: float, low: float, high: float, levels: int = 21) -> tuple[np.ndarray, float]:
    """Brute force over a grid of `levels`^H sequences."""
    grid = np.linspace(low, high, levels)
    seqs = np.array(list(itertools.product(grid, repeat=H)))  # [levels^H, H]
    cost = _cost_np(seqs, p0, v0)
    i = int(cost.argmin())
    return seqs[i], float(cost[i])


CFG = CEMConfig(horizon=H, candidates=1000, top_k=100, iterations=10)


def _plan(p0, v0, low, high, cfg=CFG, seed=0, init_mean=None):
    p0_t, v0_t = torch.tensor(p0, dtype=torch.float32), torch.tensor(v0, dtype=torch.float32)
    lo = torch.tensor(low, dtype=torch.float32)[:, None]
    hi = torch.tensor(high, dtype=torch.float32)[:, None]
    return cem_plan(_score_fn(p0_t, v0_t), lo, hi, cfg, torch.Generator().manual_seed(seed), init_mean)


def test_cem_finds_the_closed_form_optimum_and_beats_the_grid():
    p0, v0 = 1.5, -0.5
    exact = _closed_form(p0, v0)
    assert np.abs(exact).max() < 1.0  # the bounds are inactive: the closed form is the optimum
    grid_seq, grid_cost = _grid_best(p0, v0, -1.0, 1.0)
    out = _plan([p0], [v0], [-1.0], [1.0])
    plan = out.mean[0, :, 0].numpy().astype(np.float64)
    np.testing.assert_allclose(plan, exact, atol=0.02)  # stated tolerance: 0.02 per action
    cem_cost = float(_cost_np(plan, p0, v0))
    assert cem_cost <= grid_cost + 1e-6  # at least as good as the best of 21^4 grid sequences
    assert cem_cost <= float(_cost_np(exact, p0, v0)) + 1e-3
    assert np.abs(grid_seq - exact).max() <= 0.05 + 1e-9  # the grid's best is the optimum's nearest point


def test_cem_respects_active_bounds_as_the_grid_does():
    p0, v0, lim = 6.0, 0.0, 0.5  # far away, small actions: the first action is pinned at the bound
    grid_seq, grid_cost = _grid_best(p0, v0, -lim, lim)
    out = _plan([p0], [v0], [-lim], [lim])
    plan = out.mean[0, :, 0].numpy().astype(np.float64)
    assert plan.min() >= -lim - 1e-6 and plan.max() <= lim + 1e-6
    assert abs(plan[0] - grid_seq[0]) < 0.02 and grid_seq[0] == -lim
    assert float(_cost_np(plan, p0, v0)) <= grid_cost + 1e-3


def test_rows_with_different_models_and_bounds_do_not_interact():
    p0, v0, low, high = [1.5, -2.0, 6.0], [-0.5, 0.3, 0.0], [-1.0, -2.0, -0.5], [1.0, 2.0, 0.5]
    together = _plan(p0, v0, low, high)
    # each row reaches its own optimum
    for i in (0, 1):
        np.testing.assert_allclose(together.mean[i, :, 0].numpy(), _closed_form(p0[i], v0[i]), atol=0.03)
    # changing the other rows' models and bounds leaves row 0 bit-identical
    changed = _plan([p0[0], 9.0, -3.0], [v0[0], 1.0, 2.0], [low[0], -0.1, -5.0], [high[0], 0.1, 5.0])
    assert torch.equal(together.mean[0], changed.mean[0]) and torch.equal(together.std[0], changed.std[0])
    assert not torch.equal(together.mean[1], changed.mean[1])


def test_fixed_generator_reproduces_and_seeds_differ():
    a, b, c = (_plan([1.5], [-0.5], [-1.0], [1.0], seed=s) for s in (3, 3, 4))
    assert torch.equal(a.mean, b.mean)
    assert not torch.equal(a.mean, c.mean)


def test_warm_start_shifts_the_plan_and_is_used():
    mean = torch.arange(6, dtype=torch.float32).reshape(1, 3, 2)  # [E, H, A]
    low, high = torch.tensor([[-1.0, 0.0]]), torch.tensor([[1.0, 4.0]])
    shifted = shift_plan(mean, low, high)
    assert torch.equal(shifted, torch.tensor([[[2.0, 3.0], [4.0, 5.0], [0.0, 2.0]]]))
    # one iteration with K = J: the refit mean is the candidates' mean, near the initial mean
    cfg = CEMConfig(horizon=H, candidates=4000, top_k=4000, iterations=1, init_std=0.05)
    init = torch.full((1, H, 1), 0.7)
    out = _plan([1.5], [-0.5], [-1.0], [1.0], cfg=cfg, init_mean=init)
    np.testing.assert_allclose(out.mean.numpy(), 0.7, atol=0.01)


def test_bad_planner_config_is_one_line():
    with pytest.raises(ValueError, match="top_k") as err:
        _plan([1.0], [0.0], [-1.0], [1.0], cfg=CEMConfig(candidates=10, top_k=20))
    assert "\n" not in str(err.value)


def test_the_same_planner_serves_a_goal_cost():
    """Score = minus the distance of the rollout's last state to a per-row goal (as a goal
    embedding would be): a 2-D point x' = x + a from the origin ends at its row's goal."""
    goals = torch.tensor([[1.5, -0.5], [-2.0, 2.5]])  # [E, 2], reachable in H = 4 steps of |a| <= 1

    def goal_score(actions: torch.Tensor) -> torch.Tensor:  # [E, J, H, 2] -> [E, J]
        final = actions.sum(2)  # x_H from x_0 = 0
        return -(final - goals[:, None]).norm(dim=-1)

    low, high = -torch.ones(2, 2), torch.ones(2, 2)
    out = cem_plan(goal_score, low, high, CFG, torch.Generator().manual_seed(0))
    np.testing.assert_allclose(out.mean.sum(1).numpy(), goals.numpy(), atol=0.05)
