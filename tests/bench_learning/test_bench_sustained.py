"""Issue 24: runs judged on a sustained mean (last three evals at the budget), the first env
step from which that mean stays at/above the target, and compare's mean curve with a band."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from wmdist.bench import compare, learning
from wmdist.bench.learning import cpu_info, first_reaching, sustained
from wmdist.telemetry.curves import write_jsonl

PRESET = str(Path(__file__).resolve().parents[2] / "configs" / "dreamerv3_cartpole.yaml")  # checked, never run


def _jsonl(path, evals: list[tuple[int, float]]):
    """A metrics.jsonl with a train record, the evals (time = env steps / 100) and noise."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_jsonl(path, {"kind": "train", "env_steps": 0, "time": 0.0, "train_return": 9999.0})
    for s, r in evals:
        write_jsonl(path, {"kind": "eval", "env_steps": s, "eval_return": r, "time": s / 100})
        write_jsonl(path, {"kind": "train", "env_steps": s + 1, "time": s / 100, "train_return": 9999.0})
    write_jsonl(path, {"kind": "eval", "env_steps": 10**9, "eval_return": None, "time": 1e9})
    return path


def _curve(path, returns: list[float]):
    return _jsonl(path, [(1000 * (i + 1), r) for i, r in enumerate(returns)])


def test_last_three_mean_at_a_budget_ignores_evals_past_it(tmp_path):
    f = _curve(tmp_path / "m.jsonl", [100, 500, 500, 500, 0, 0])  # collapses after 4000 steps
    whole = sustained(f, 475)
    assert whole["last3_mean"] == pytest.approx(500 / 3) and not whole["met"]
    assert whole["sustained_from_env_steps"] is None and whole["evals"] == 6
    for kw in ({"budget_env_steps": 4000}, {"budget_seconds": 40.0}, {"budget_env_steps": 4500, "budget_seconds": 45}):
        at = sustained(f, 475, **kw)
        assert at["evals"] == 4 and at["last3_mean"] == 500 and at["met"], kw
        assert at["sustained_from_env_steps"] == 4000 and at["sustained_from_seconds"] == 40.0
        assert at["final_env_steps"] == 4000 and at["final_eval_return"] == 500
    # the budget also bounds the first crossing
    assert sustained(f, 475, budget_env_steps=1500)["reached"] is False
    assert first_reaching(f, 475, budget_env_steps=1500)["reached"] is False


def test_sustained_step_is_the_start_of_the_final_stretch_at_or_above_target(tmp_path):
    # 3-eval means: 367, 500 (crosses at 4000), 367, 233, 233, 367, 500 (again at 9000), 500
    f = _curve(tmp_path / "m.jsonl", [100, 500, 500, 500, 100, 100, 500, 500, 500, 500])
    r = sustained(f, 475)
    assert r["sustained_from_env_steps"] == 9000 and r["sustained_from_seconds"] == 90.0
    assert r["met"] and r["last3_mean"] == 500
    assert r["reached"] and r["env_steps_to_target"] == 2000  # first crossing kept beside it
    assert r["seconds_to_target"] == 20.0


def test_a_mean_exactly_at_target_counts(tmp_path):
    r = sustained(_curve(tmp_path / "m.jsonl", [0, 475, 475, 475]), 475)
    assert r["met"] and r["sustained_from_env_steps"] == 4000


def test_crossing_then_ending_below_is_not_sustained(tmp_path):
    r = sustained(_curve(tmp_path / "m.jsonl", [100, 500, 500, 500, 500, 100, 100]), 475)
    assert r["reached"] and r["env_steps_to_target"] == 2000
    assert not r["met"] and r["sustained_from_env_steps"] is None and r["sustained_from_seconds"] is None
    assert r["last3_mean"] == pytest.approx(700 / 3)


@pytest.mark.parametrize("returns", [[], [500], [500, 500]])
def test_fewer_than_three_evals_is_not_met(tmp_path, returns):
    r = sustained(_curve(tmp_path / "m.jsonl", returns), 475)
    assert r["last3_mean"] is None and r["met"] is False
    assert r["sustained_from_env_steps"] is None and r["reached"] is bool(returns)


def test_cpu_info_names_the_model_and_bf16_flags(tmp_path):
    f = tmp_path / "cpuinfo"
    f.write_text("processor\t: 0\nmodel name\t: Fancy CPU @ 3GHz\nflags\t\t: fpu sse avx512_bf16 avx512f\n\n"
                 "processor\t: 1\nmodel name\t: Other\nflags\t\t: fpu amx_bf16\n")
    assert cpu_info(str(f)) == {"cpu": "Fancy CPU @ 3GHz", "cpu_avx512_bf16": True, "cpu_amx_bf16": False}
    assert set(cpu_info(str(tmp_path / "missing"))) == {"cpu", "cpu_avx512_bf16", "cpu_amx_bf16"}


def test_learning_main_reports_sustained_figures_at_the_budget(tmp_path, monkeypatch, capsys):
    curves = {0: [100, 500, 500, 500, 0, 0], 1: [500, 100, 100, 100, 100, 100]}

    def fake_train(cmd, **kw):  # stands in for `wmdist train`: writes the run folder the bench reads
        sets = dict(x.split("=", 1) for x in cmd if "=" in x)
        seed = int(sets["run.seed"])
        _curve(tmp_path / "runs" / f"{sets['run.name']}-20260101-000000" / "metrics.jsonl", curves[seed])
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(learning.subprocess, "run", fake_train)
    png = tmp_path / "l.png"
    assert learning.main([PRESET, "--seeds", "0", "1", "--target", "475", "--png", str(png),
                          "--runs-dir", str(tmp_path / "runs"), "--budget-env-steps", "4000",
                          "--budget-minutes", "1"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.strip().splitlines()]
    seeds = {r["seed"]: r for r in rows if "run_dir" in r}
    assert seeds[0]["met"] and seeds[0]["last3_mean"] == 500 and seeds[0]["sustained_from_env_steps"] == 4000
    assert seeds[0]["budget_env_steps"] == 4000 and seeds[0]["budget_seconds"] == 60
    assert seeds[1]["reached"] and not seeds[1]["met"] and seeds[1]["sustained_from_env_steps"] is None
    for r in seeds.values():
        assert {"cpu", "cpu_avx512_bf16", "cpu_amx_bf16", "env_steps_to_target"} <= set(r)
    summary = rows[-1]
    assert summary["met"] == "1/2" and summary["reached"] == "2/2"
    assert summary["max_sustained_from_env_steps"] == 4000
    assert png.stat().st_size > 1000


def test_compare_refuses_groups_it_cannot_plot(tmp_path, capsys):
    _curve(tmp_path / "ok" / "preset-seed0-20261122-000000" / "metrics.jsonl", [100, 500])
    (tmp_path / "empty").mkdir()
    png = tmp_path / "cmp.png"
    for bad, says in (("nolabel", "expected GROUP=DIR"), (f"x={tmp_path / 'missing'}", "is not a folder"),
                      (f"x={tmp_path / 'empty'}", "holds no run folders")):
        assert compare.main(["--target", "1", "--png", str(png), f"ok={tmp_path / 'ok'}", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and says in err[0], err
    assert not png.exists()  # nothing half-plotted


def test_learning_bench_reports_progress_while_a_seed_trains(tmp_path, monkeypatch, capsys):
    import time

    old = tmp_path / "runs" / "dreamerv3_cartpole-seed0-20250101-000000"  # an earlier run of the seed
    _curve(old / "metrics.jsonl", [999])

    def slow_train(cmd, **kw):  # a run that has logged two evals and is still going
        sets = dict(x.split("=", 1) for x in cmd if "=" in x)
        _curve(tmp_path / "runs" / f"{sets['run.name']}-20260101-000000" / "metrics.jsonl", [120, 240])
        time.sleep(0.6)
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(learning.subprocess, "run", slow_train)
    assert learning.main([PRESET, "--seeds", "0", "--target", "475", "--png", str(tmp_path / "l.png"),
                          "--runs-dir", str(tmp_path / "runs"), "--progress-seconds", "0.1"]) == 0
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.startswith("wmdist: seed 0: ")]
    assert lines and "2,000 env steps" in lines[-1] and "last eval 240.0" in lines[-1], captured.err
    assert "999" not in captured.err  # the older run's figures are not this run's
    assert all(ln.startswith("{") for ln in captured.out.strip().splitlines())  # stdout: JSON lines only


def test_a_seed_that_fails_after_start_up_is_reported_with_its_error_and_not_met(tmp_path, monkeypatch, capsys):
    def crashing_train(cmd, **kw):  # logged three evals at the target, then died
        sets = dict(x.split("=", 1) for x in cmd if "=" in x)
        _curve(tmp_path / "runs" / f"{sets['run.name']}-20260101-000000" / "metrics.jsonl", [500, 500, 500])
        return subprocess.CompletedProcess(cmd, 1, "", "wmdist: error while training: boom; resume with ...")

    monkeypatch.setattr(learning.subprocess, "run", crashing_train)
    assert learning.main([PRESET, "--seeds", "3", "--target", "475", "--png", str(tmp_path / "l.png"),
                          "--runs-dir", str(tmp_path / "runs"), "--progress-seconds", "0"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.strip().splitlines()]
    assert rows[0]["seed"] == 3 and "boom" in rows[0]["error"][0] and rows[0]["last3_mean"] == 500
    assert rows[0]["met"] is False and rows[-1]["met"] == "0/1"
    assert (tmp_path / "l.png").exists()  # its curve is drawn with the others


def test_band_interpolates_each_seed_only_inside_its_span():
    grid, mean, lo, hi = compare.band([([0, 2000], [0.0, 200.0]), ([1000, 4000], [300.0, 600.0])])
    assert grid == [0, 1000, 2000, 4000]
    assert mean == [0.0, 200.0, 300.0, 600.0]  # 1000: (100+300)/2, 2000: (200+400)/2; 0 and 4000: one seed
    assert lo == [0.0, 100.0, 200.0, 600.0] and hi == [0.0, 300.0, 400.0, 600.0]
    assert compare.band([]) == ([], [], [], [])


def test_compare_prints_sustained_figures_per_run_and_group(tmp_path, capsys):
    def run(group, seed, returns):
        _curve(tmp_path / group / f"preset-seed{seed}-20261122-000000" / "metrics.jsonl", returns)

    run("a", 0, [100, 500, 500, 500])
    run("a", 1, [100, 500, 500, 100, 100])
    run("b", 0, [10, 20, 500, 500, 500])
    run("b", 1, [10, 500, 500, 500, 500, 500, 500])
    png = tmp_path / "cmp.png"
    assert compare.main(["--target", "475", "--png", str(png), f"a={tmp_path / 'a'}", f"b={tmp_path / 'b'}"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert all("last3_mean" in line for line in out) and len(out) == 6
    rows = [json.loads(x) for x in out]
    per = {(r["group"], r["seed"]): r for r in rows if "seed" in r}
    assert per[("a", 0)]["met"] and per[("a", 0)]["sustained_from_env_steps"] == 4000
    assert per[("a", 1)]["reached"] and not per[("a", 1)]["met"]  # crossed, then fell back
    assert per[("b", 1)]["sustained_from_env_steps"] == 4000 and per[("b", 1)]["env_steps_to_target"] == 2000
    groups = {r["group"]: r for r in rows if "seed" not in r}
    assert groups["a"]["met"] == 1 and groups["a"]["reached"] == 2 and groups["a"]["runs"] == 2
    assert groups["a"]["mean_env_steps_to_target"] == 2000  # the old keys are still there
    assert groups["b"]["met"] == 2 and groups["b"]["last3_mean"] == 500
    assert groups["b"]["sustained_from_env_steps"] == [5000, 4000] and groups["b"]["max_sustained_from_env_steps"] == 5000
    assert png.stat().st_size > 1000
    # a budget judges the same runs at 4000 env steps
    assert compare.main(["--target", "475", "--png", str(png), "--budget-env-steps", "4000",
                         f"b={tmp_path / 'b'}"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.strip().splitlines()]
    assert [r["met"] for r in rows] == [False, True, 1]


def test_a_run_name_given_with_set_names_the_runs_the_bench_then_finds(tmp_path, monkeypatch, capsys):
    """`--set run.name=X` (the same preset on another game, say) once renamed the run away from
    where the bench looked: the run trained, and the bench reported no run directory."""
    def fake_train(cmd, **kw):  # as `wmdist train`: the last `run.name=` wins
        sets = dict(x.split("=", 1) for x in cmd if "=" in x)
        _curve(tmp_path / "runs" / f"{sets['run.name']}-20260101-000000" / "metrics.jsonl", [500, 500, 500])
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(learning.subprocess, "run", fake_train)
    assert learning.main([PRESET, "--seeds", "0", "--target", "475", "--png", str(tmp_path / "l.png"),
                          "--runs-dir", str(tmp_path / "runs"), "--progress-seconds", "0",
                          "--set", "run.name=other-game"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.strip().splitlines()]
    assert rows[0]["met"] and rows[0]["run_dir"].endswith("other-game-seed0-20260101-000000"), rows[0]
