"""JEPA's learner (wmdist/algos/jepa/learner.py): history windows against a loop, and the
predictor's loss falling on the point mass's deterministic dynamics, from data the runtime's
own collector gathers into replay (the local runner's LocalSession)."""
from __future__ import annotations

import dataclasses

import numpy as np
import torch

from tests.algos.local_config import local_run_config
from wmdist.algos.jepa import Jepa, JepaConfig
from wmdist.algos.jepa.learner import history_windows
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec
from wmdist.runtime.local import LocalSession


def small_config(**kw) -> JepaConfig:
    base = dict(cnn_depth=8, embed_dim=8, proj_hidden=64, pred_hidden=64, sigreg_projections=32, lr=1e-3)
    cfg = JepaConfig(**{**base, **kw})
    cfg.planner = dataclasses.replace(cfg.planner, horizon=3, candidates=32, top_k=4, iterations=3)
    return cfg


def test_history_windows_match_a_loop():
    x = torch.arange(2 * 6 * 3, dtype=torch.float32).reshape(2, 6, 3)  # [B, T, F]
    for h in (1, 2, 3):
        got = history_windows(x, h)  # [B, T-h, h, F]
        want = torch.stack([torch.stack([x[:, t - h + 1 + i] for i in range(h)], 1) for t in range(h - 1, 5)], 1)
        assert got.shape == (2, 6 - h, h, 3)
        torch.testing.assert_close(got, want)


def test_predictor_loss_falls_on_deterministic_dynamics_from_collected_data():
    env_cfg = EnvConfig(id="nav:open")
    algo = Jepa(env_spec(env_cfg), small_config(), seed=0)
    session = LocalSession(local_run_config(algo, env_cfg, num_envs=4, seq_len=6, overlap=3, seed=0, batch_size=8))
    try:
        session.collect(150)  # reward-free random exploration: 600 env steps
        assert session.env_steps == 600 and session.stored_count() > 50
        fixed = [session.sample(16) for _ in range(3)]
        learner = session.learner

        def scores() -> tuple[float, float]:
            with torch.no_grad():
                parts = [learner.loss(b)[1] for b in fixed]
            return float(np.mean([p["pred_loss"] for p in parts])), float(np.mean([p["effective_rank"] for p in parts]))

        start, _ = scores()
        metrics = session.train(120)
        end, rank = scores()
    finally:
        session.close()
    assert all(np.isfinite(m["loss"]) for m in metrics)
    # embeddings keep unit scale (BatchNorm projector, SIGReg), so a smaller MSE is a better predictor
    assert end < 0.5 * start, (start, end)
    assert rank > 3.0  # not collapsed onto a line


def test_predictor_dropout_acts_while_training_and_is_off_when_planning():
    from wmdist.algos.jepa.model import JepaModel
    torch.manual_seed(0)
    model = JepaModel(small_config(pred_dropout=0.5), action_dim=2)
    assert any(isinstance(m, torch.nn.Dropout) for m in model.predictor)
    z, a = torch.randn(16, 1, 8), torch.randn(16, 1, 2)  # [N, h, D], [N, h, A]
    model.train()
    assert not torch.allclose(model.predict(z, a), model.predict(z, a))  # a fresh mask per call
    model.eval()
    torch.testing.assert_close(model.predict(z, a), model.predict(z, a))
    plain = JepaModel(small_config(), action_dim=2)
    assert not any(isinstance(m, torch.nn.Dropout) for m in plain.predictor)  # default 0: no layer at all


def test_rollout_loss_equals_a_plain_loop_over_the_predictors_own_steps():
    """algo.rollout_steps K: each window's first embedding rolled forward K times by the
    predictor (its own outputs fed back), each step compared with the real embedding; steps
    past an episode's end are left out."""
    from wmdist.algos.jepa.model import FRAME_CHANNELS

    spec = env_spec(EnvConfig(id="nav:open"))
    learner = Jepa(spec, small_config(rollout_steps=3, pred_dropout=0.0), seed=0).make_learner()
    learner.model.eval()  # running BatchNorm statistics, so the loop's single rows embed as the batch does
    rng = np.random.default_rng(0)
    b, t_len = 3, 5
    batch = {"obs": rng.integers(0, 255, size=(b, t_len, 64, 64, 6), dtype=np.uint8),
             "action": rng.uniform(-1, 1, size=(b, t_len, 2)).astype(np.float32),
             "mask": np.ones((b, t_len), bool)}
    batch["mask"][2, 2:] = False  # row 2's episode ends after its second step: only its first prediction counts
    with torch.no_grad():
        _, metrics = learner.loss(batch)
        total, count = 0.0, 0
        for r in range(b):
            z = learner.model.encode(torch.as_tensor(batch["obs"][r:r + 1, :, :, :, :FRAME_CHANNELS]))[0]  # [T, D]
            z_hat = z[0][None, None]  # [1, h=1, D]
            for k in range(3):
                a = torch.as_tensor(batch["action"][r, k])[None, None]  # [1, 1, A]
                z_hat = learner.model.predict(z_hat, a)[:, None]  # [1, 1, D]: fed back, not the real z
                if batch["mask"][r, k + 1]:
                    total += float(((z_hat[0, 0] - z[k + 1]) ** 2).mean())
                    count += 1
    assert count == 7
    np.testing.assert_allclose(metrics["pred_loss"], total / count, rtol=1e-4)
    learner1 = Jepa(spec, small_config(pred_dropout=0.0), seed=0).make_learner()  # K = 1: the teacher-forced loss
    learner1.model.load_state_dict(learner.model.state_dict())
    learner1.model.eval()
    with torch.no_grad():
        assert abs(learner1.loss(batch)[1]["pred_loss"] - metrics["pred_loss"]) > 1e-4  # not the same loss


def test_rollout_steps_longer_than_the_windows_is_a_one_line_config_error():
    from pathlib import Path

    import pytest

    from wmdist.config.errors import ConfigError
    from wmdist.config.loader import load_config
    from wmdist.runtime.preflight import check_env_and_algo

    preset = str(Path(__file__).parents[3] / "configs" / "jepa_nav_tworooms.yaml")
    cfg = load_config(preset, ["algo.rollout_steps=3"])  # the preset's windows hold 2 steps
    with pytest.raises(ConfigError) as err:
        check_env_and_algo(cfg)
    assert "needs replay.seq_len >= algo.history + rollout_steps = 4, got 2" in str(err.value)
    check_env_and_algo(load_config(preset, ["algo.rollout_steps=3", "replay.seq_len=4"]))  # long enough: no error
