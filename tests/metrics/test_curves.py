"""Run outputs: JSONL appends and the learning-curve PNG, robust to partial and torn files."""
from __future__ import annotations

import json

import pytest

from wmdist.telemetry.metrics import MetricsHub
from wmdist.telemetry.curves import _loss_series, _return_points, plot_learning_curve, read_jsonl, write_jsonl

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _is_png(path) -> bool:
    data = path.read_bytes()
    return data[:8] == PNG_MAGIC and len(data) > 5000


def test_write_jsonl_appends_strict_json(tmp_path):
    import numpy as np

    path = tmp_path / "metrics.jsonl"
    write_jsonl(path, {"env_steps": np.int64(5), "loss/total": float("nan"), "x": np.float32(0.5)})
    write_jsonl(path, {"env_steps": 10, "v": [1.0, float("inf")]})
    lines = path.read_text().splitlines()
    assert [json.loads(ln) for ln in lines] == [
        {"env_steps": 5, "loss/total": None, "x": 0.5},
        {"env_steps": 10, "v": [1.0, None]},
    ]
    with pytest.raises(ValueError, match="must be a dict"):
        write_jsonl(path, [1, 2])


def test_driver_log_with_a_torn_last_line_plots(tmp_path):
    path = tmp_path / "metrics.jsonl"
    for i in range(1, 30):
        write_jsonl(path, {"time": i, "env_steps": 100 * i, "updates": 10 * i, "kind": "train",
                           "train_return": None if i < 3 else float(i), "loss/total": 5.0 / i, "loss/value": 1.0})
        if i % 10 == 0:
            write_jsonl(path, {"time": i, "env_steps": 100 * i, "updates": 10 * i, "kind": "eval", "eval_return": 2.0 * i})
    with open(path, "a") as f:
        f.write('{"time": 31, "env_ste')  # the writer is mid-line
    records = list(read_jsonl(path))
    assert len(records) == 31
    assert _return_points(records, "train") == ([100.0 * i for i in range(3, 30)], [float(i) for i in range(3, 30)])
    assert _return_points(records, "eval") == ([1000.0, 2000.0], [20.0, 40.0])
    assert sorted(_loss_series(records)) == ["total", "value"]
    png = tmp_path / "out" / "curve.png"
    plot_learning_curve(path, png)
    assert _is_png(png)
    assert not [p for p in png.parent.iterdir() if p.name != "curve.png"]  # no temp file left


def test_hub_snapshots_keep_only_reports_with_new_episodes(tmp_path):
    hub = MetricsHub()
    path = tmp_path / "m.jsonl"
    for i in range(6):
        hub.set("wmdist_env_steps_total", 50 * i)
        hub.set("wmdist_episodes_total", i // 2, role="eval")  # new eval episodes at i = 2, 4
        if i >= 2:
            hub.set("wmdist_episode_return", float(i), role="eval")
        hub.set("wmdist_learner_updates_total", i)
        hub.set("wmdist_learner_loss", 1.0 / (i + 1), name="policy")
        write_jsonl(path, hub.snapshot())
    records = list(read_jsonl(path))
    assert _return_points(records, "eval") == ([100.0, 200.0], [2.0, 4.0])
    assert _loss_series(records)["policy"][0] == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    plot_learning_curve(path, tmp_path / "c.png")
    assert _is_png(tmp_path / "c.png")


def test_empty_or_missing_file_still_gives_a_png(tmp_path):
    plot_learning_curve(tmp_path / "none.jsonl", tmp_path / "a.png")
    (tmp_path / "junk.jsonl").write_text("not json\n[1, 2]\n")
    plot_learning_curve(tmp_path / "junk.jsonl", tmp_path / "b.png")
    assert _is_png(tmp_path / "a.png") and _is_png(tmp_path / "b.png")
