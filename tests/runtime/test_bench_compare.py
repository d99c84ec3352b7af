"""`python -m wmdist.bench.compare`: steps to target per seed and per group, one plot."""
from __future__ import annotations

import json

from wmdist.bench.compare import curve, main


def _run(folder, seed: int, evals: list[tuple[int, float]]) -> None:
    d = folder / f"preset-seed{seed}-20261122-000000"
    d.mkdir(parents=True)
    lines = [{"kind": "train", "env_steps": 0, "time": 0.0}] + [
        {"kind": "eval", "env_steps": s, "eval_return": r, "time": s / 100} for s, r in evals]
    (d / "metrics.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def test_compare_reports_first_crossing_per_seed_and_group_means(tmp_path, capsys):
    _run(tmp_path / "a", 0, [(1000, 100.0), (2000, 480.0), (3000, 300.0)])
    _run(tmp_path / "a", 1, [(1000, 200.0), (4000, 500.0)])
    _run(tmp_path / "b", 0, [(1000, 10.0), (2000, 20.0)])
    png = tmp_path / "cmp.png"
    assert main(["--target", "475", "--png", str(png), f"a={tmp_path / 'a'}", f"b={tmp_path / 'b'}"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.strip().splitlines()]
    per_seed = {(r["group"], r["seed"]): r for r in rows if "seed" in r}
    assert per_seed[("a", 0)]["env_steps_to_target"] == 2000  # the first crossing, not the last eval
    assert per_seed[("a", 1)]["env_steps_to_target"] == 4000
    assert not per_seed[("b", 0)]["reached"]
    groups = {r["group"]: r for r in rows if "seed" not in r}
    assert groups["a"]["mean_env_steps_to_target"] == 3000 and groups["b"]["reached"] == 0
    assert png.stat().st_size > 1000


def test_compare_rejects_a_group_without_a_folder(tmp_path, capsys):
    assert main(["--target", "1", "--png", str(tmp_path / "x.png"), "nofolder"]) == 2
    assert "GROUP=DIR" in capsys.readouterr().err


def test_compare_plots_return_against_wall_time(tmp_path, capsys):
    records = [{"kind": "eval", "env_steps": 1000, "eval_return": 5.0, "time": 90.0},
               {"kind": "eval", "env_steps": 3000, "eval_return": 9.0, "time": 300.0}]
    assert curve(records, "minutes") == ([1.5, 5.0], [5.0, 9.0])
    assert curve(records, "env_steps") == ([1000, 3000], [5.0, 9.0])
    _run(tmp_path / "a", 0, [(1000, 100.0), (2000, 480.0)])
    png = tmp_path / "t.png"
    assert main(["--target", "475", "--x", "minutes", "--budget-minutes", "1", "--png", str(png),
                 f"a={tmp_path / 'a'}"]) == 0
    assert png.stat().st_size > 1000
