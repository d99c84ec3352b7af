"""A short run of every preset in configs/ on the 2-CPU local Ray instance: the whole
runtime with the real algorithm, and the (world-)model loss falls."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wmdist.config.loader import load_config
from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.roles import build_algorithm
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

CONFIGS = Path(__file__).parents[2] / "configs"
PRESETS = sorted(p.name for p in CONFIGS.glob("*.yaml") if p.name != "base.yaml")

# Keep each run short: small warm-up, no evaluator, no metrics server, one collector.
SHORT = ["eval.every_seconds=0", "metrics.enabled=false", "checkpoint.every_seconds=0", "actors.num=1",
         "run.log_every_seconds=0.5", "run.max_env_steps=0"]
# Smoke presets (pixels, Atari) only have to run; their loss is checked over fewer updates.
BUDGET = {"muzero_atari.yaml": ["run.max_updates=6", "run.max_minutes=3", "replay.min_size=200",
                                "actors.envs_per_actor=2", "learner.batch_size=4"],
          "dreamerv3_dmc_pixels.yaml": ["run.max_updates=6", "run.max_minutes=3", "replay.min_size=100",
                                        "learner.batch_size=4"]}
DEFAULT_BUDGET = ["run.max_updates=60", "run.max_minutes=2", "replay.min_size=300"]


def _loss_key(algo_name: str) -> str:
    return "model_loss" if algo_name == "dreamer" else "loss"


@pytest.mark.parametrize("preset", PRESETS)
def test_preset_runs_and_its_loss_falls(ray_session, tmp_path, preset):
    cfg = load_config(CONFIGS / preset, [f"run.dir={tmp_path}", *SHORT, *BUDGET.get(preset, DEFAULT_BUDGET)])
    spec = env_spec_or_error(cfg)
    topo = build(cfg, spec, tmp_path, build_algorithm(cfg, spec, 0).step_fields())
    key = _loss_key(cfg.algo_name)
    losses: list[float] = []

    def record(snap: dict) -> None:
        if key in snap["losses"] and (not losses or snap["losses"][key] != losses[-1]):
            losses.append(snap["losses"][key])

    try:
        result = Driver(topo, Counters(), on_tick=record).run()
    finally:
        topo.shutdown()
    assert result.status == "done", result.message
    assert result.counters.updates >= 6 and result.counters.env_steps > 0
    assert len(losses) >= 2, losses
    head, tail = np.mean(losses[:2]), np.mean(losses[-2:])
    assert tail < head, f"{preset}: {key} did not fall: {losses}"
