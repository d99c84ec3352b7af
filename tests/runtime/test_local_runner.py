"""The Ray-free local runner (`wmdist train --local`, `ray.local: true`): the same collector,
learner, reanalyzer and evaluator code in one process. It stores exactly the records the
Ray runtime stores, and every preset takes its first steps under it."""
from __future__ import annotations

import io
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from wmdist.config.loader import load_config
from wmdist.runtime import checkpoint as ck
from wmdist.runtime.train import train

HERE = Path(__file__).parent
CONFIGS = HERE.parents[1] / "configs"
PRESETS = sorted(p.name for p in CONFIGS.glob("*.yaml") if p.name != "base.yaml")
QUIET = ["metrics.enabled=false", "metrics.tensorboard=false", "eval.every_seconds=0", "checkpoint.every_seconds=0"]


def _run(tmp_path: Path, config: str, overrides: list[str]) -> Path:
    cfg = load_config(config, [f"run.dir={tmp_path}", *QUIET, *overrides])
    out = io.StringIO()
    code = train(cfg=cfg, out=out)
    assert code == 0, out.getvalue()
    runs = sorted(p for p in tmp_path.iterdir() if p.is_dir())
    assert len(runs) == 1
    return runs[0]


def _replay_arrays(run_dir: Path) -> dict[str, np.ndarray]:
    ckpt = ck.latest_checkpoint(run_dir)
    assert ckpt is not None
    out = {}
    for f in sorted((ckpt / "replay").glob("*.npz")):
        with np.load(f, allow_pickle=False) as z:
            out.update({f"{f.stem}/{k}": z[k] for k in z.files})
    return out


def test_local_and_ray_store_the_same_records(ray_session, tmp_path):
    """Same seed, deterministic env (CartPole), one collector, one shard, weights fixed at
    version 0 (replay below min_size: no update): every stored array is equal."""
    same = ["actors.num=1", "replay.shards=1", "run.max_env_steps=400", "run.max_minutes=2",
            "replay.min_size=20000", "run.seed=3"]  # the whole capacity: never reached
    ray_run = _run(tmp_path / "ray", str(HERE / "fake.yaml"), same)
    local_run = _run(tmp_path / "local", str(HERE / "fake.yaml"), [*same, "ray.local=true"])
    a, b = _replay_arrays(ray_run), _replay_arrays(local_run)
    assert sorted(a) == sorted(b)
    assert any(k.endswith("obs") or "obs" in k for k in a), sorted(a)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    counters = [json.loads((ck.latest_checkpoint(r) / "counters.json").read_text()) for r in (ray_run, local_run)]
    assert counters[0]["env_steps"] == counters[1]["env_steps"] >= 400


def test_local_runner_resumes_and_never_starts_ray(tmp_path):
    """A local run trains, checkpoints and resumes without ever starting Ray in this process
    (run in a subprocess so another test's Ray instance cannot hide one started here)."""
    import subprocess

    code = f"""
import io, sys
from wmdist.config.loader import load_config
from wmdist.runtime.train import train
cfg = load_config({str(HERE / 'fake.yaml')!r}, ["run.dir={tmp_path}", "ray.local=true", "run.max_updates=20",
                  "run.max_minutes=1", {', '.join(repr(q) for q in QUIET)}])
assert train(cfg=cfg, out=io.StringIO()) == 0
ray = sys.modules.get("ray")
assert ray is None or not ray.is_initialized(), "the local runner started Ray"
print("OK")
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240,
                         cwd=str(HERE.parents[1]))
    assert res.returncode == 0 and "OK" in res.stdout, res.stderr[-2000:]
    run_dir = next(p for p in tmp_path.iterdir() if p.is_dir())
    first = json.loads((ck.latest_checkpoint(run_dir) / "counters.json").read_text())
    assert first["updates"] >= 20
    out = io.StringIO()
    assert train(resume=str(run_dir), overrides=["run.max_updates=30"], out=out) == 0, out.getvalue()
    assert "resumed from" in out.getvalue()
    again = json.loads((ck.latest_checkpoint(run_dir) / "counters.json").read_text())
    assert again["updates"] >= 30 and again["env_steps"] >= first["env_steps"]


# Presets whose full-size networks take seconds per step on a CPU get the preset test's smoke sizes.
def _smoke_overrides(preset: str) -> list[str]:
    from tests.runtime.test_presets import BUDGET

    return [o for o in BUDGET.get(preset, []) if not o.startswith(("run.max_updates", "run.max_env_steps"))]


@pytest.mark.parametrize("preset", PRESETS)
def test_every_preset_takes_its_first_steps_locally(preset, tmp_path):
    """Collectors fill replay and the learner makes a first update, all in this process, whose
    priority stays as it was (a role's `nice` is for its own Ray process)."""
    before = os.getpriority(os.PRIO_PROCESS, 0)
    run = _run(tmp_path, str(CONFIGS / preset),
               [*_smoke_overrides(preset), "ray.local=true", "actors.num=1", "run.max_updates=1",
                "run.max_env_steps=0", "run.max_minutes=2", "replay.min_size=32", "learner.batch_size=2",
                "actors.segment_steps=8",
                "reanalyze.batch_size=2", "metrics.tensorboard=false"])
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert max(r["updates"] for r in records) >= 1, records[-1]
    assert max(r["env_steps"] for r in records) > 0
    assert os.getpriority(os.PRIO_PROCESS, 0) == before
