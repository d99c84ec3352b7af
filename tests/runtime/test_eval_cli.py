"""`wmdist eval RUN_DIR` plays greedy episodes from a run's latest checkpoint (no Ray needed)."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from tests.runtime.one_line import one_line_exit_2
from wmdist.cli import main
from wmdist.config.loader import dump_yaml, load_config
from wmdist.runtime.checkpoint import save_checkpoint

CFG = str(Path(__file__).parent / "fake.yaml")


def _run_dir(tmp_path: Path, w: np.ndarray) -> Path:
    cfg = load_config(CFG, [f"run.dir={tmp_path}"])
    run_dir = tmp_path / "run"
    run_dir.mkdir(parents=True)
    (run_dir / "config.yaml").write_text(dump_yaml(cfg))
    save_checkpoint(run_dir, {"w": w}, {"w": w}, 7, {"updates": 3, "env_steps": 100}, None, keep=2)
    return run_dir


def test_eval_prints_greedy_returns_of_the_checkpoint(tmp_path, capsys):
    # a linear policy that pushes the cart toward the pole's lean balances far longer than one that pushes away
    good = np.array([[0, 0], [0, 0], [-1, 1], [-1, 1]], np.float32)
    bad = -good
    returns = {}
    for name, w in (("good", good), ("bad", bad)):
        run_dir = _run_dir(tmp_path / name, w)
        assert main(["eval", str(run_dir), "--episodes", "4"]) == 0
        out = capsys.readouterr().out
        assert "weights v7" in out and "mean return" in out
        returns[name] = float(out.split("mean return ")[1].split()[0])
    assert returns["good"] > 3 * returns["bad"], returns


def test_eval_reports_progress_on_stderr(tmp_path, capsys):
    from wmdist.runtime.evaluate import evaluate_run

    good = np.array([[0, 0], [0, 0], [-1, 1], [-1, 1]], np.float32)
    run_dir = _run_dir(tmp_path, good)
    assert evaluate_run(str(run_dir), episodes=4, progress_seconds=0.0) == 0
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.startswith("wmdist: eval: ")]
    assert [ln.split()[2] for ln in lines] == ["1/4", "2/4", "3/4", "4/4"], captured.err
    mean = float(captured.out.split("mean return ")[1].split()[0])
    assert lines[-1].endswith(f"mean return {mean:.2f}")  # the last progress line is the result
    assert "wmdist: eval:" not in captured.out  # stdout keeps the result lines only


def test_eval_of_a_folder_without_checkpoint_is_one_line(tmp_path, capsys):
    assert main(["eval", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "not a wmdist run directory" in err and err.count("\n") == 1


def test_eval_of_a_damaged_checkpoint_is_one_line_naming_the_older_one(tmp_path, capsys):
    w = np.zeros((4, 2), np.float32)
    run_dir = _run_dir(tmp_path, w)
    save_checkpoint(run_dir, {"w": w}, {"w": w}, 9, {"updates": 5, "env_steps": 200}, None, keep=2)
    older, newer = sorted((run_dir / "checkpoints").iterdir())
    (newer / "weights.npz").write_bytes(b"PK\x03\x04 cut short by a full disk")
    assert main(["eval", str(run_dir), "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot be read" in err and older.name in err, err
    (newer / "weights.npz").unlink()
    (newer / "counters.json").write_text('{"version": ')  # the counters, too, are read by eval
    assert main(["eval", str(run_dir), "--episodes", "1"]) == 2
    assert "cannot be read" in capsys.readouterr().err
    shutil.rmtree(newer)  # the fall-back the line suggests works
    assert main(["eval", str(run_dir), "--episodes", "1"]) == 0


def test_board_bench_plays_the_solver_and_plots_losses(tmp_path, capsys):
    import json

    from wmdist.bench.board import main as board_main
    from wmdist.envs.factory import env_spec
    from wmdist.runtime.roles.setup import build_algorithm

    preset = Path(__file__).parents[2] / "configs" / "muzero_tictactoe.yaml"
    cfg = load_config(str(preset), [f"run.dir={tmp_path}", "algo.search.num_simulations=4", "algo.hidden=[8]",
                                    "algo.latent_dim=8"])
    run_dir = tmp_path / "ttt"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(dump_yaml(cfg))
    weights = build_algorithm(cfg, env_spec(cfg.env), 0).make_learner().get_weights()
    save_checkpoint(run_dir, {}, weights, 3, {"updates": 3, "env_steps": 90}, None, keep=2)
    (run_dir / "metrics.jsonl").write_text(
        '{"kind": "eval", "env_steps": 40, "eval_return": -0.5, "eval_min": -1, "time": 60}\n'
        '{"kind": "eval", "env_steps": 90, "eval_return": -0.1, "eval_min": -1, "time": 120, '
        '"eval_lost_lines": 3, "eval_lines": 500}\n')
    png, lines_png = tmp_path / "lost.png", tmp_path / "lines.png"
    assert board_main([str(run_dir), "--games", "6", "--png", str(png), "--lines-png", str(lines_png)]) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert res["games"] == 6 and res["won_p0"] == res["won_p1"] == 0  # nobody beats the solver
    assert sum(res[f"{k}_p{s}"] for k in ("won", "drew", "lost") for s in (0, 1)) == 6
    assert res["never_loses"] == (res["lost"] == 0)
    # every line judged too: an untrained net loses some, and the per-side counts add up
    assert res["lost_lines"] == res["lost_lines_p0"] + res["lost_lines_p1"] > 0
    assert png.stat().st_size > 1000 and lines_png.stat().st_size > 1000


def test_board_bench_on_connect4_plays_the_runs_uct_opponent_and_plots_games_won(tmp_path, capsys):
    import json

    from wmdist.bench.board import main as board_main
    from wmdist.envs.factory import env_spec
    from wmdist.runtime.roles.setup import build_algorithm

    preset = Path(__file__).parents[2] / "configs" / "muzero_connect4.yaml"
    cfg = load_config(str(preset), [f"run.dir={tmp_path}", "algo.search.num_simulations=2", "algo.hidden=[8]",
                                    "algo.latent_dim=8", "eval.opponent_rollouts=7"])
    run_dir = tmp_path / "c4"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(dump_yaml(cfg))
    weights = build_algorithm(cfg, env_spec(cfg.env), 0).make_learner().get_weights()
    save_checkpoint(run_dir, {}, weights, 3, {"updates": 3, "env_steps": 90}, None, keep=2)
    (run_dir / "metrics.jsonl").write_text(
        '{"kind": "eval", "env_steps": 40, "eval_return": -0.8, "eval_min": -1, "eval_won": 0.1, "time": 60}\n'
        '{"kind": "eval", "env_steps": 90, "eval_return": 0.2, "eval_min": -1, "eval_won": 0.6, "time": 120}\n')
    png = tmp_path / "won.png"
    assert board_main([str(run_dir), "--games", "4", "--png", str(png)]) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert res["opponent"] == "UCT (7 rollouts per move)"  # the run's own eval.opponent_rollouts, not the default
    assert res["games"] == 4 and res["won_fraction"] == res["won"] / 4
    assert "lost_lines" not in res  # the whole-tree judge is for tic-tac-toe only
    assert png.stat().st_size > 1000
    versus = tmp_path / "old.jsonl"
    versus.write_text('{"net": "old", "minutes": 2.0, "won": 0.05}\n{"net": "old", "minutes": 4.0, "won": null}\n')
    both = tmp_path / "both.png"
    assert board_main([str(run_dir), "--games", "2", "--png", str(both), "--versus", str(versus)]) == 0
    assert both.stat().st_size > png.stat().st_size // 2


def _one_line_exit_2(capsys, argv: list[str]) -> str:
    line, out = one_line_exit_2(capsys, argv)
    assert "mean return" not in out  # failed before playing anything
    return line


def test_a_config_edited_after_training_is_one_line_naming_the_mismatch(tmp_path, capsys):
    from tests.runtime.run_dirs import run_dir_with_checkpoint

    run = run_dir_with_checkpoint(tmp_path, "muzero_cartpole")
    text = (run / "config.yaml").read_text()
    assert "latent_dim: 32" in text
    (run / "config.yaml").write_text(text.replace("latent_dim: 32", "latent_dim: 48"))
    for argv in (["eval", str(run), "--episodes", "1"], ["dream", str(run)]):
        line = _one_line_exit_2(capsys, argv)
        assert "does not fit the model" in line and "size mismatch" in line and "config.yaml" in line


def test_output_paths_are_checked_before_any_episode(tmp_path, capsys):
    run = _run_dir(tmp_path, np.zeros((4, 2), np.float32))
    line = _one_line_exit_2(capsys, ["eval", str(run), "--episodes", "1", "--video", str(tmp_path / "no" / "v.gif")])
    assert "no such folder" in line
    line = _one_line_exit_2(capsys, ["eval", str(run), "--episodes", "1", "--video", str(tmp_path)])
    assert "is a folder" in line
    line = _one_line_exit_2(capsys, ["dream", str(run), "--out", str(tmp_path / "no" / "d.gif")])
    assert "no such folder" in line
