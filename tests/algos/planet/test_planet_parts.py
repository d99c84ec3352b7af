"""PlaNet in-process: bad planner configs are one-line config errors; the learner's loss falls
on a fixed batch; the policy plans for E envs at once within the bounds; `wmdist dream` works."""
from pathlib import Path

import numpy as np
import pytest
import torch

from wmdist.algos.base import PLANS, PREDICTS_OBSERVATIONS
from wmdist.algos.planet import PlaNet, PlaNetConfig
from wmdist.bench.dreamer import random_batch
from wmdist.cli import main
from wmdist.config.errors import ConfigError
from wmdist.config.loader import load_config
from wmdist.envs.spec import EnvSpec
from wmdist.search.cem import CEMConfig

CONFIGS = Path(__file__).parents[3] / "configs"
STATE = str(CONFIGS / "planet_dmc_cartpole_swingup.yaml")
SPEC = EnvSpec("test:cont", (5,), "float32", "vector", action_shape=(2,), action_low=(-1.0, 0.0), action_high=(1.0, 2.0))
TINY = dict(deter=16, stoch=4, units=16, mlp_layers=1, planner=CEMConfig(horizon=3, candidates=20, top_k=4, iterations=2))


@pytest.mark.parametrize("override, words", [
    ("algo.planner.top_k=2000", "algo.planner.top_k (2000) must not exceed algo.planner.candidates (100)"),
    ("algo.planner.horizon=0", "algo.planner.horizon"),
    ("algo.overshooting_distance=1", "overshooting_distance"),
])
def test_bad_planner_config_is_one_config_error_line(override, words):
    with pytest.raises(ConfigError) as err:
        load_config(STATE, [override])
    assert words in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("preset", ["planet_dmc_cartpole_swingup.yaml", "planet_dmc_cartpole_swingup_pixels.yaml"])
def test_presets_use_the_papers_action_repeat_and_planner_horizon(preset):
    from wmdist.algos.planet.config import ACTION_REPEAT

    cfg = load_config(str(CONFIGS / preset))
    domain = cfg.env.id.split(":")[1].split("-")[0]
    assert cfg.env.action_repeat == ACTION_REPEAT[domain] == 8
    assert cfg.algo.planner.horizon == 12 and cfg.algo.expl_noise == 0.3 and (cfg.algo.deter, cfg.algo.stoch) == (200, 30)


def test_continuous_planner_on_a_discrete_env_is_one_config_error_line():
    from wmdist.runtime.preflight import check_env_and_algo

    cfg = load_config(STATE, ["env.id=gym:CartPole-v1", "env.action_repeat=1"])
    with pytest.raises(ConfigError) as err:
        check_env_and_algo(cfg)
    assert "continuous actions" in str(err.value) and "\n" not in str(err.value)


def test_capabilities_are_declared():
    assert PlaNet.offers(PREDICTS_OBSERVATIONS) and PlaNet.offers(PLANS)


def test_learner_loss_falls_on_a_fixed_batch_with_overshooting():
    learner = PlaNet(SPEC, PlaNetConfig(**TINY, overshooting_distance=3, free_nats=0.0)).make_learner()
    batch = random_batch(SPEC, 4, 10)
    losses = [learner.update(batch).metrics for _ in range(30)]
    assert losses[-1]["model_loss"] < 0.97 * losses[0]["model_loss"]  # random observations: most of the loss is noise
    assert all(np.isfinite(m["overshooting_kl"]) for m in losses)
    state = learner.state_dict()  # resumes exactly
    again = PlaNet(SPEC, PlaNetConfig(**TINY, overshooting_distance=3, free_nats=0.0)).make_learner()
    again.load_state_dict(state)
    assert again.update(batch).metrics["model_loss"] == learner.update(batch).metrics["model_loss"]


def test_policy_plans_for_every_env_within_the_bounds_and_noise_only_when_exploring():
    algo = PlaNet(SPEC, PlaNetConfig(**TINY, expl_noise=5.0))  # huge noise: clipped to the bounds
    policy = algo.make_policy()
    policy.set_weights(algo.make_learner().get_weights(), 1)
    obs = np.random.default_rng(0).normal(size=(3, 5)).astype(np.float32)
    seen = []
    for explore in (True, False):
        for step in range(3):
            action, extras = policy.act(obs, np.array([step == 0] * 3), None, None, explore)
            assert action.shape == (3, 2) and action.dtype == np.float32 and extras == {}
            assert (action[:, 0] >= -1).all() and (action[:, 0] <= 1).all()
            assert (action[:, 1] >= 0).all() and (action[:, 1] <= 2).all()
            seen.append(action)
    explored = np.concatenate(seen[:3])
    assert np.isin(explored, [-1.0, 1.0, 0.0, 2.0]).mean() > 0.5  # noise 5 pushes most actions onto a bound
    planned = np.concatenate(seen[3:])
    assert np.isin(planned, [-1.0, 1.0, 0.0, 2.0]).mean() < 0.5  # the plan's mean of the elites, no noise


def test_untrained_collector_acts_at_random_without_planning(monkeypatch):
    import wmdist.algos.planet.policy as policy_module

    algo = PlaNet(SPEC, PlaNetConfig(**TINY))
    policy = algo.make_policy()
    policy.set_weights(algo.make_learner().get_weights(), 0)  # the learner's initial snapshot
    monkeypatch.setattr(policy_module, "cem_plan", lambda *a, **k: pytest.fail("planned with an untrained model"))
    obs = np.zeros((64, 5), np.float32)
    action, _ = policy.act(obs, np.ones(64, bool), None, None, True)
    assert action[:, 0].min() < -0.5 and action[:, 0].max() > 0.5  # uniform over [-1, 1]
    assert action[:, 1].min() < 0.5 and action[:, 1].max() > 1.5 and (action[:, 1] >= 0).all()  # over [0, 2]
    assert policy.h is not None and torch.isfinite(policy.h).all()  # the posterior still followed the observation


def test_warm_start_policy_keeps_the_shifted_plan():
    cfg = PlaNetConfig(**{**TINY, "planner": CEMConfig(horizon=3, candidates=20, top_k=4, iterations=2, warm_start=True)})
    policy = PlaNet(SPEC, cfg).make_policy()
    obs = np.zeros((2, 5), np.float32)
    policy.act(obs, np.array([True, True]), None, None, False)
    assert policy.plan is not None and policy.plan.shape == (2, 3, 2)
    policy.act(obs, np.array([False, True]), None, None, False)
    assert torch.isfinite(policy.plan).all()


def test_dream_on_a_planet_run_writes_the_video(tmp_path, capsys):
    from tests.runtime.run_dirs import run_dir_with_checkpoint

    tiny = ["algo.deter=16", "algo.units=16", "algo.stoch=4", "algo.planner.candidates=10", "algo.planner.top_k=2",
            "algo.planner.iterations=1", "algo.planner.horizon=2"]
    run_dir = run_dir_with_checkpoint(tmp_path, "planet_dmc_cartpole_swingup", tiny)
    assert main(["dream", str(run_dir), "--horizon", "5"]) == 0
    assert "dream video" in capsys.readouterr().out
    assert (run_dir / "dream.gif").stat().st_size > 0


def test_planner_bench_reports_decisions_and_the_model_share():
    from wmdist.bench.planner import preset_planner, time_planner

    assert preset_planner().candidates == 100  # the state preset's planner is what the bench reads
    r = time_planner(CEMConfig(horizon=3, candidates=16, top_k=4, iterations=2), envs=2, min_seconds=0.05)
    assert r["decisions_per_s"] > 0 and r["decisions_per_cpu_s"] > 0
    assert 0.3 < r["model_share"] <= 1.0  # the rollouts dominate even for a tiny planner
