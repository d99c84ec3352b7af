"""`wmdist dream RUN --error`: open-loop prediction error by horizon against a plain per-start loop,
the no-change figure against numpy, and the command's output and refusals."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from tests.algos.dreamer.dreamer_loop import tiny_config
from tests.runtime.one_line import one_line_exit_2
from tests.runtime.run_dirs import run_dir_with_checkpoint
from wmdist.algos.dream_error import HorizonError, add_episode_errors, default_horizons, format_errors
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.planet import PlaNet, PlaNetConfig
from wmdist.cli import main
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_model
from wmdist.nets.dists import symexp

SPEC = EnvSpec("test:cont", (3,), "float32", "vector", action_shape=(1,), action_low=(-2.0,), action_high=(2.0,))


def _reference(wm, spec, obs, actions, horizons, stride):
    """Per start t and horizon k, one at a time: filter o_0..o_t from scratch with posterior modes,
    roll the prior's modes k steps with the real actions, decode; sums of squared errors [D]."""
    rssm, t_len = wm.rssm, len(obs)
    act = action_to_model(torch.as_tensor(actions), spec)
    model = {k: np.zeros(obs.shape[1]) for k in horizons}
    still = {k: np.zeros(obs.shape[1]) for k in horizons}
    count = {k: 0 for k in horizons}
    with torch.no_grad():
        for t in range(0, t_len - 1, stride):
            h, z = rssm.initial(1)
            for i in range(t + 1):
                a_prev = torch.zeros(1, act.shape[-1]) if i == 0 else act[i - 1:i]
                h = rssm.img_step(h, z, rssm.action_part(a_prev), torch.full((1, 1), float(i > 0)))
                z = rssm.mode(rssm.post(h, rssm.embed_part(wm.encode(torch.as_tensor(obs[i:i + 1])))))
            for k in range(1, max(horizons) + 1):
                if t + k >= t_len:
                    break
                h = rssm.img_step(h, z, rssm.action_part(act[t + k - 1:t + k]))
                z = rssm.mode(rssm.prior(h))
                if k in horizons:
                    pred = wm.decode(h, z).float()
                    pred = (symexp(pred) if wm.cfg.symlog_targets else pred).numpy()[0]
                    model[k] += (pred - obs[t + k]) ** 2
                    still[k] += (obs[t] - obs[t + k]) ** 2
                    count[k] += 1
    return model, still, count


@pytest.mark.parametrize("make", [
    lambda: PlaNet(SPEC, PlaNetConfig(deter=16, stoch=4, units=16, mlp_layers=1)),  # Gaussian latent
    lambda: Dreamer(SPEC, tiny_config(3)),  # categorical latent, symlog targets
], ids=["planet", "dreamerv3"])
def test_errors_equal_a_plain_per_start_loop(make):
    torch.manual_seed(0)
    algo = make()
    wm = algo.world_model(algo.make_learner().get_weights()).eval()
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(9, 3)).astype(np.float32) * 3  # [T, D]
    actions = rng.uniform(-2, 2, size=(9, 1)).astype(np.float32)  # [T, A] env units
    horizons = [1, 2, 4]
    errors = {k: HorizonError(k) for k in horizons}
    add_episode_errors(wm, SPEC, obs, actions, errors, stride=2)  # no generator: the modes
    model, still, count = _reference(wm, SPEC, obs, actions, horizons, stride=2)
    for k in horizons:
        assert errors[k].count == count[k] > 0
        np.testing.assert_allclose(errors[k].model_sq, model[k], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(errors[k].still_sq, still[k], rtol=1e-6)
    # starts 0, 2, 4, 6 of 9 steps: k = 4 has a real o_{t+4} for t = 0, 2, 4 only
    assert [errors[k].count for k in horizons] == [4, 4, 3]
    m, s = errors[1].rms()
    np.testing.assert_allclose(s, np.sqrt(((obs[[0, 2, 4, 6]] - obs[[1, 3, 5, 7]]) ** 2).mean(0)), rtol=1e-6)


def test_the_table_summarises_with_the_median_ratio_over_moving_dimensions():
    e = HorizonError(1)
    # per dimension: model 0.5 vs 1 (ratio 0.5), 3 vs 1 (3), 0.1 vs 1 (0.1), 0.2 vs 0 (never moves: left out)
    e.add(np.array([[0.25, 9.0, 0.01, 0.04]]), np.array([[1.0, 1.0, 1.0, 0.0]]))
    row = format_errors({1: e}, ["a", "b", "c", "d"])[1]
    assert row.split()[-1] == "0.50"


def test_default_horizons_double_up_to_the_limit():
    assert default_horizons(16) == [1, 2, 4, 8, 16]
    assert default_horizons(12) == [1, 2, 4, 8, 12]
    assert default_horizons(1) == [1]


def test_dream_error_on_a_planet_run_prints_the_table_and_writes_json(tmp_path, capsys):
    tiny = ["algo.deter=16", "algo.units=16", "algo.stoch=4", "algo.planner.candidates=10", "algo.planner.top_k=2",
            "algo.planner.iterations=1", "algo.planner.horizon=2", "env.time_limit=12"]
    run_dir = run_dir_with_checkpoint(tmp_path, "planet_dmc_cartpole_swingup", tiny)
    assert main(["dream", str(run_dir), "--error", "--episodes", "1", "--horizon", "4"]) == 0
    out = capsys.readouterr().out
    assert "dream error" in out and "obs[4]" in out and "median ratio" in out
    report = json.loads((run_dir / "dream_error.json").read_text())
    assert [r["horizon"] for r in report["rows"]] == [1, 2, 4]
    assert report["steps"] == 12 and report["rows"][0]["starts"] == 11  # every step but the last has a next one
    assert all(len(r["model_rms"]) == 5 and np.isfinite(r["model_rms"]).all() for r in report["rows"])


def test_dream_error_refuses_a_model_without_an_rssm_and_two_reports_at_once(tmp_path, capsys):
    run_dir = run_dir_with_checkpoint(tmp_path / "mz", "muzero_cartpole")
    line, _ = one_line_exit_2(capsys, ["dream", str(run_dir), "--error"])
    assert "RSSM world model" in line and "muzero" in line
    line, _ = one_line_exit_2(capsys, ["dream", str(run_dir), "--error", "--check"])
    assert "--check and --error" in line


def test_image_errors_are_one_figure_per_frame_in_unit_scale():
    spec = EnvSpec("test:img", (64, 64, 3), "uint8", "image", action_shape=(1,), action_low=(-1.0,), action_high=(1.0,))
    algo = PlaNet(spec, PlaNetConfig(deter=8, stoch=4, units=8, mlp_layers=1, cnn_depth=2))
    wm = algo.world_model(algo.make_learner().get_weights()).eval()
    rng = np.random.default_rng(1)
    obs = rng.integers(0, 256, size=(4, 64, 64, 3), dtype=np.uint8)
    errors = {1: HorizonError(1), 2: HorizonError(2)}
    add_episode_errors(wm, spec, obs, rng.uniform(-1, 1, (4, 1)).astype(np.float32), errors)
    model, still = errors[1].rms()
    assert model.shape == still.shape == (1,) and errors[1].count == 3 and errors[2].count == 2
    frames = obs.astype(np.float64) / 255.0
    np.testing.assert_allclose(still, np.sqrt(((frames[:3] - frames[1:]) ** 2).mean()), rtol=1e-5)
    assert 0.0 < model[0] < 1.0  # a [0, 1] prediction of [0, 1] frames
