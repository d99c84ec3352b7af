"""Goal-conditioned planning (wmdist/algos/jepa/planning.py, policy.py) and JEPA's bad input."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from tests.algos.jepa.test_jepa_learning import small_config
from wmdist.algos.jepa import Jepa
from wmdist.algos.jepa.model import JepaModel
from wmdist.algos.jepa.planning import goal_distance_fn, rollout
from wmdist.config.schema import RunConfig
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec, make_env
from wmdist.envs.spec import EnvSpec
from wmdist.search.cem import CEMConfig, cem_plan

SPEC = env_spec(EnvConfig(id="nav:tworooms"))


class _Shift(JepaModel):
    """A model whose predictor is known: the embedding is a 2-D position moved by 0.1 x action."""

    def predict(self, z_hist, a_hist):  # type: ignore[override]
        return z_hist[:, -1] + 0.1 * a_hist[:, -1]


def test_rollout_with_history_matches_step_by_step_prediction():
    torch.manual_seed(0)
    model = JepaModel(small_config(history=2), action_dim=2).eval()
    z_hist, a_past, actions = torch.randn(3, 2, 8), torch.randn(3, 1, 2), torch.randn(3, 4, 2)
    got = rollout(model, z_hist, a_past, actions)  # [3, 4, 8]
    zs, acts = list(z_hist.unbind(1)), [a_past[:, 0]]
    for k in range(4):
        acts.append(actions[:, k])
        zs.append(model.predict(torch.stack(zs[-2:], 1), torch.stack(acts[-2:], 1)))
    torch.testing.assert_close(got, torch.stack(zs[2:], 1))


def test_goal_costs_against_a_step_by_step_computation():
    """last, sum and min of the squared distances along the imagined path, by hand on the known model;
    a plan that passes through the goal and walks on is best under `min` alone."""
    model = _Shift(small_config(embed_dim=2), action_dim=2)
    z0, goal = torch.tensor([[0.0, 0.0]]), torch.tensor([[0.2, 0.0]])  # [E=1, D]
    actions = torch.tensor([[[[1.0, 0.0]] * 4,  # passes the goal at step 2, ends 0.2 beyond it
                             [[0.5, 0.0]] * 4,  # ends on the goal
                             [[0.0, 1.0]] * 4]])  # walks away   -> [E=1, J=3, H=4, A=2]
    want = {c: [] for c in ("last", "sum", "min")}
    for j in range(3):
        pos, dists = z0[0].clone(), []
        for k in range(4):
            pos = pos + 0.1 * actions[0, j, k]
            dists.append(float(((pos - goal[0]) ** 2).sum()))
        want["last"].append(-dists[-1])
        want["sum"].append(-sum(dists))
        want["min"].append(-min(dists))
    for cost, expected in want.items():
        got = goal_distance_fn(model, z0[:, None], torch.zeros(1, 0, 2), goal, cost)(actions)  # [1, 3]
        np.testing.assert_allclose(got[0].numpy(), expected, rtol=1e-5, atol=1e-7)
    by_min = goal_distance_fn(model, z0[:, None], torch.zeros(1, 0, 2), goal, "min")(actions)[0]
    assert float(by_min[0]) == pytest.approx(0.0, abs=1e-7) and float(by_min[0]) >= float(by_min[1])
    with pytest.raises(ValueError, match="goal cost"):
        goal_distance_fn(model, z0[:, None], torch.zeros(1, 0, 2), goal, "mean")


def test_step_cost_prefers_the_earlier_arrival():
    """min_k (d_k + beta k) by hand; both plans pass through the goal, the detour later, and only a step cost
    tells them apart."""
    model = _Shift(small_config(embed_dim=2), action_dim=2)
    z0, goal = torch.tensor([[0.0, 0.0]]), torch.tensor([[0.2, 0.0]])
    straight = [[1.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]  # there at step 2, stays
    detour = [[0.0, 1.0], [0.0, 1.0], [1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, -1.0]]  # there at step 6
    actions = torch.tensor([[straight, detour]])  # [E=1, J=2, H=6, A=2]
    for beta in (0.0, 0.01):
        want = []
        for j in range(2):
            pos, costs = z0[0].clone(), []
            for k in range(6):
                pos = pos + 0.1 * actions[0, j, k]
                costs.append(float(((pos - goal[0]) ** 2).sum()) + beta * (k + 1))
            want.append(-min(costs))
        got = goal_distance_fn(model, z0[:, None], torch.zeros(1, 0, 2), goal, "min", step_cost=beta)(actions)[0]
        np.testing.assert_allclose(got.numpy(), want, rtol=1e-5, atol=1e-7)
        if beta == 0.0:
            assert float(got[0]) == pytest.approx(float(got[1]), abs=1e-7)  # both reach it: a tie
        else:
            assert float(got[0]) > float(got[1]) + 0.03  # 0.01 x (6 - 2) apart


@pytest.mark.parametrize("cost,tolerance", [("sum", 0.02), ("last", 0.1), ("min", 0.1)])
def test_cem_moves_toward_the_goal_embedding_and_mpc_reaches_it(cost, tolerance):
    model = _Shift(small_config(embed_dim=2), action_dim=2)
    cfg = CEMConfig(horizon=4, candidates=200, top_k=20, iterations=5)
    g = torch.Generator().manual_seed(0)
    z = torch.tensor([[0.0, 0.0], [0.5, 0.5]])  # [E, D]
    goal = torch.tensor([[0.3, -0.2], [0.5, 0.9]])
    low, high = -torch.ones(2, 2), torch.ones(2, 2)
    for _ in range(15):  # MPC: replan every step, take the first action (the last-step cost spreads the move)
        plan = cem_plan(goal_distance_fn(model, z[:, None], torch.zeros(2, 0, 2), goal, cost), low, high, cfg, g)
        z = z + 0.1 * plan.action
    # "last" leaves the first action to the elites' noise: it gets near and jitters there
    assert float((z - goal).norm(dim=-1).max()) < tolerance


def _trained_weights(algo: Jepa, updates: int) -> dict:
    weights = algo.make_learner().get_weights()
    weights["jepa.updates"] = np.asarray(updates, np.int64)
    return weights


def test_policy_plans_for_every_env_within_bounds():
    algo = Jepa(SPEC, small_config(), seed=0)
    policy = algo.make_policy()
    policy.set_weights(_trained_weights(algo, 5), 1)
    env = make_env(EnvConfig(id="nav:tworooms"), 0)
    obs = np.stack([env.reset() for _ in range(3)])
    for first in (np.ones(3, bool), np.zeros(3, bool)):
        action, extras = policy.act(obs, first, None, None, explore=False)
        assert action.shape == (3, 2) and action.dtype == np.float32 and extras == {}
        assert np.all(np.abs(action) <= 1.0)


def test_collectors_explore_without_the_model():
    algo = Jepa(SPEC, small_config(explore_keep=0.5), seed=0)
    policy = algo.make_policy()  # untrained: exploring needs no weights
    obs = np.zeros((4, 64, 64, 6), np.uint8)
    actions = [policy.act(obs, np.zeros(4, bool), None, None, explore=True)[0] for _ in range(200)]
    repeats = np.mean([np.array_equal(a[0], b[0]) for a, b in zip(actions, actions[1:])])
    assert 0.35 < repeats < 0.65  # the previous action kept with probability explore_keep
    assert np.all(np.abs(np.stack(actions)) <= 1.0)


def test_planning_before_any_training_is_one_line():
    algo = Jepa(SPEC, small_config(), seed=0)
    policy = algo.make_policy()
    policy.set_weights(algo.make_learner().get_weights(), 0)  # the learner's initial snapshot
    obs = np.zeros((2, 64, 64, 6), np.uint8)
    with pytest.raises(ValueError, match="before any training") as err:
        policy.act(obs, np.ones(2, bool), None, None, explore=False)
    assert "\n" not in str(err.value)


def test_a_goal_image_of_the_wrong_shape_is_one_line():
    algo = Jepa(SPEC, small_config(), seed=0)
    policy = algo.make_policy()
    policy.set_weights(_trained_weights(algo, 5), 1)
    for shape in ((2, 64, 64, 3), (2, 64, 64, 7), (2, 32, 32, 6)):
        with pytest.raises(ValueError, match="goal image") as err:
            policy.act(np.zeros(shape, np.uint8), np.ones(2, bool), None, None, explore=False)
        assert "\n" not in str(err.value)
    frames = EnvSpec(id="dmc:reacher-easy", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image",
                     action_shape=(2,), action_low=(-1.0, -1.0), action_high=(1.0, 1.0))
    with pytest.raises(ValueError, match=r"goal image.*\[64, 64, 3\]"):
        Jepa(frames, small_config())


def test_check_run_refuses_evaluations_that_could_come_before_training():
    algo = Jepa(SPEC, small_config(), seed=0)
    run = RunConfig()
    run.replay = dataclasses.replace(run.replay, min_size=1000, seq_len=8)
    run.eval = dataclasses.replace(run.eval, every_seconds=60.0, every_env_steps=0)
    with pytest.raises(ValueError, match="every_seconds"):
        algo.check_run(run)
    run.eval = dataclasses.replace(run.eval, every_seconds=0.0, every_env_steps=500)
    with pytest.raises(ValueError, match="min_size"):
        algo.check_run(run)
    run.eval = dataclasses.replace(run.eval, every_env_steps=2000)
    algo.check_run(run)
    run.replay = dataclasses.replace(run.replay, seq_len=1)
    with pytest.raises(ValueError, match="seq_len"):
        algo.check_run(run)


def test_embedding_plot_of_a_planned_episode(tmp_path):
    from wmdist.algos.jepa.trajectory_plot import planned_episode

    algo = Jepa(SPEC, small_config(), seed=0)
    weights = _trained_weights(algo, 5)
    env = make_env(EnvConfig(id="nav:tworooms"), 0)
    ep = planned_episode(algo, weights, env, steps=4)
    steps = len(ep["planned"])
    assert ep["real"].shape == (steps + 1, 8) and ep["planned"].shape == (steps, 3, 8) and ep["goal"].shape == (8,)
    path = algo.embedding_plot(weights, make_env(EnvConfig(id="nav:tworooms"), 0), str(tmp_path / "plan.png"), steps=4)
    assert (tmp_path / "plan.png").stat().st_size > 1000 and path.endswith("plan.png")
