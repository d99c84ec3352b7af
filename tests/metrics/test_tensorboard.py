"""Every run writes TensorBoard event files holding the same scalars as its metrics.jsonl
(read back with TensorBoard's own event reader), and `wmdist monitor` says how to open them."""
from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

from wmdist.config.loader import load_config
from wmdist.runtime.train import train
from wmdist.telemetry.tensorboard import TB_DIR, read_image_tags, read_scalars, scalars_of

FAKE = str(Path(__file__).parents[1] / "runtime" / "fake.yaml")


def test_scalars_of_keeps_numbers_and_skips_the_rest():
    rec = {"time": 1.5, "env_steps": 10, "updates": 3, "kind": "train", "train_return": None,
           "loss/value": 0.25, "flag": True, "version": 2, "bad": float("nan")}
    assert scalars_of(rec) == {"train/updates": 3.0, "train/loss/value": 0.25, "train/version": 2.0}


@pytest.fixture(scope="module")
def short_run(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("tb")
    cfg = load_config(FAKE, [f"run.dir={tmp}", "ray.local=true", "run.max_env_steps=800", "run.max_minutes=1",
                             "run.log_every_seconds=0.2", "eval.every_env_steps=200",
                             "metrics.enabled=false"])
    out = io.StringIO()
    assert train(cfg=cfg, out=out) == 0, out.getvalue()
    return next(p for p in tmp.iterdir() if p.is_dir())


def test_event_files_hold_the_metrics_jsonl_scalars(short_run):
    records = [json.loads(line) for line in (short_run / "metrics.jsonl").read_text().splitlines()]
    want: dict[str, list[tuple[int, float]]] = {}
    for rec in records:
        for tag, value in scalars_of(rec).items():
            want.setdefault(tag, []).append((rec["env_steps"], value))
    assert any(t.startswith("eval/") for t in want) and any(t.startswith("train/loss/") for t in want), sorted(want)
    got = read_scalars(short_run / TB_DIR)
    assert sorted(got) == sorted(want)
    for tag, series in want.items():
        assert [s for s, _ in got[tag]] == [s for s, _ in series], tag
        assert [v for _, v in got[tag]] == pytest.approx([v for _, v in series], rel=1e-6, abs=1e-6), tag
    assert "learning_curve" in read_image_tags(short_run / TB_DIR)


def test_monitor_names_the_tensorboard_command(short_run):
    res = subprocess.run([sys.executable, "-m", "wmdist.cli", "monitor", str(short_run)], capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert f"tensorboard --logdir {short_run.resolve() / TB_DIR}" in res.stdout
    assert "--host 127.0.0.1" in res.stdout


def test_dream_video_lands_in_tensorboard(tmp_path):
    """`wmdist dream` also writes its frames as a TensorBoard image sequence in the run."""
    import imageio.v2 as imageio

    from tests.runtime.run_dirs import run_dir_with_checkpoint
    from wmdist.runtime.evaluate import dream_run
    from wmdist.telemetry.tensorboard import read_image_tags

    run = run_dir_with_checkpoint(tmp_path, "dreamerv3_cartpole")
    assert dream_run(str(run), horizon=6, stream=io.StringIO()) == 0
    frames = imageio.mimread(str(run / "dream.gif"))
    assert "dream" in read_image_tags(run / TB_DIR)
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run / TB_DIR), size_guidance={"images": 0})
    acc.Reload()
    assert len(acc.Images("dream")) == len(frames)
