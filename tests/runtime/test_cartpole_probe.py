"""`python -m wmdist.bench.cartpole_probe`: how a Dreamer CartPole run's episodes end and its critic's
value by cart position; other runs and bad counts are one-line errors."""
from __future__ import annotations

import json

import numpy as np

from tests.runtime.run_dirs import run_dir_with_checkpoint
from wmdist.bench import cartpole_probe
from wmdist.bench.cartpole_probe import X_LIMIT, replay_ends

SMALL = ["algo.deter=16", "algo.units=16", "algo.stoch=4", "algo.classes=4"]


def test_probe_reports_each_episode_end_and_the_value_of_every_step(tmp_path, capsys):
    run = run_dir_with_checkpoint(tmp_path, "dreamerv3_cartpole", SMALL)
    assert cartpole_probe.main([str(run), "--episodes", "3"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    episodes, summary = lines[:-1], lines[-1]
    assert [e["episode"] for e in episodes] == [0, 1, 2]
    for e in episodes:
        assert e["end"] in {"x", "angle", "limit"}
        assert (e["end"] == "limit") == (e["length"] == 500)
        assert (e["end"] == "x") == (e["max_abs_x"] > X_LIMIT)
        assert (e["cont_at_end"] is None) == (e["end"] == "limit")  # the model's view of a real end
        assert e["cont_at_end"] is None or 0.0 <= e["cont_at_end"] <= 1.0
    assert summary["replay_ends"] is None  # this checkpoint was saved without replay
    # every step's value falls in exactly one |x| bin (the cart is on the track at every decision)
    assert sum(b["steps"] for b in summary["value_by_abs_x"]) == sum(e["length"] for e in episodes)
    assert summary["summary"] and summary["episodes"] == 3 and summary["explore"] is False


def test_probe_refuses_a_run_that_is_not_dreamer_on_cartpole_in_one_line(tmp_path, capsys):
    run = run_dir_with_checkpoint(tmp_path, "muzero_cartpole")
    assert cartpole_probe.main([str(run), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Dreamer runs on gym:CartPole-v1" in err[0]
    assert cartpole_probe.main([str(run), "--episodes", "0"]) == 2


def test_replay_ends_counts_cart_and_pole_terminations_of_valid_rows_only(tmp_path):
    ckpt = tmp_path / "ckpt"
    (ckpt / "replay").mkdir(parents=True)
    obs = np.zeros((2, 4, 4), np.float32)  # [N, T, 4]
    terminal = np.zeros((2, 4), bool)
    mask = np.ones((2, 4), bool)
    obs[0, 3] = [2.45, 0.1, 0.01, 0.0]  # the cart left the track
    terminal[0, 3] = True
    obs[1, 1] = [0.3, 0.0, 0.25, 1.0]  # the pole fell
    terminal[1, 1] = True
    obs[1, 3] = [-2.5, 0.0, 0.0, 0.0]  # a padded row's flag does not count
    terminal[1, 3], mask[1, 2:] = True, False
    np.savez(ckpt / "replay" / "shard0.npz", f_obs=obs, f_terminal=terminal, mask=mask)
    assert replay_ends(ckpt) == {"x": 1, "angle": 1, "steps": 6}
    np.savez(ckpt / "replay" / "shard1.npz", f_obs=obs, f_terminal=terminal, mask=mask)
    assert replay_ends(ckpt) == {"x": 2, "angle": 2, "steps": 12}  # every shard
