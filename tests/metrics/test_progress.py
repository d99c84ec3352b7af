"""Console progress: plain throttled lines off a TTY, in-place redraw on one, partial data shown as '-'."""
from __future__ import annotations

import io

import pytest

from wmdist.telemetry.metrics import MetricsHub
from wmdist.telemetry.progress import Progress


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class TTY(io.StringIO):
    def isatty(self) -> bool:
        return True


DRIVER_SNAP = {
    "elapsed_seconds": 30.0, "env_steps": 5000, "env_steps_per_second": 250.0, "updates": 120,
    "updates_per_second": 4.0, "train_return": 18.5, "eval_return": None, "losses": {"value": 0.2, "total": 1.25},
    "replay": {"shard0_size_steps": 3000, "shard1_size_steps": 1500, "shard0_inserts": 9}, "version": 12, "version_gap": 2,
}


def test_partial_snapshot_prints_dashes_not_errors():
    out = io.StringIO()
    p = Progress(10_000, 5.0, out, clock=FakeClock())
    p.update({})
    p.update({"env_steps": 100})  # throttled: same instant
    p.close()
    lines = out.getvalue().splitlines()
    assert len(lines) == 2  # the first report, then the unseen last one on close
    assert "steps -/10k (-)" in lines[0] and "loss -" in lines[0] and "eta 5m00s" in lines[0]
    assert lines[1].startswith("steps 100/10k (1%)")


def test_driver_snapshot_fields_and_eta_from_the_nearer_limit():
    clock = FakeClock()
    out = io.StringIO()
    p = Progress(10_000, 60.0, out, clock=clock)
    line = p.format(DRIVER_SNAP)
    assert "steps 5k/10k (50%)" in line and "250/s" in line
    assert "upd 120" in line and "ret train 18.5" in line and "eval -" in line
    assert "loss 1.25" in line  # the algorithm's total loss
    assert "replay 4.5k" in line  # summed over shards, inserts not counted
    assert "w v12 gap 2" in line
    assert "30s eta 20s" in line  # 5000 steps left at 250/s beats 59.5 minutes left


def test_hub_snapshot_spelling_is_read_too():
    hub = MetricsHub()
    hub.set("wmdist_env_steps_total", 700)
    hub.set("wmdist_episode_return", 9.0, role="eval")
    hub.set("wmdist_learner_loss", 0.75, name="reward")
    hub.set("wmdist_replay_size_steps", 40, shard="0")
    hub.set("wmdist_replay_size_steps", 60, shard="1")
    line = Progress(0, 0, io.StringIO()).format(hub.snapshot())
    assert line.startswith("steps 700 |")  # no step limit: no total, no percentage
    assert "eval 9" in line and "loss 0.75" in line and "replay 100" in line and "eta -" in line


def test_plain_lines_are_throttled_and_tty_redraws_in_place():
    clock = FakeClock()
    out = io.StringIO()
    p = Progress(1000, 1.0, out, plain_every_s=10.0, clock=clock)
    for i in range(5):  # one report per second
        p.update({"env_steps": i * 10})
        clock.t += 1.0
    clock.t += 10.0
    p.update({"env_steps": 500})
    p.close()
    assert [ln.split(" |")[0] for ln in out.getvalue().splitlines()] == ["steps 0/1k (0%)", "steps 500/1k (50%)"]

    tty = TTY()
    p = Progress(1000, 1.0, tty, clock=clock)
    p.update({"env_steps": 1})
    p.update({"env_steps": 2})
    p.close()
    text = tty.getvalue()
    assert text.count("\r") == 2 and text.endswith("\n") and text.count("\n") == 1


def test_negative_limits_are_refused():
    with pytest.raises(ValueError, match="total_env_steps"):
        Progress(-1, 1.0, io.StringIO())
    with pytest.raises(ValueError, match="total_minutes"):
        Progress(10, -1.0, io.StringIO())


def test_a_stage_without_a_loss_shows_its_named_headline_instead():
    # World Models' controller search reports fitnesses, no loss: `headline_fitness` names its figure,
    # where the first metric by name (`cma_best_fitness`) would have been shown as a "loss"
    p = Progress(0, 60.0, io.StringIO(), clock=FakeClock())
    snap = {**DRIVER_SNAP, "losses": {"cma_best_fitness": 918.0, "cma_gen_mean": 400.0, "headline_fitness": 843.0}}
    line = p.format(snap)
    assert "fitness 843" in line and "loss" not in line
    hub = MetricsHub()
    hub.set("wmdist_learner_loss", 12.5, name="headline_fitness")
    hub.set("wmdist_learner_loss", 1.0, name="aaa")
    assert "fitness 12.5" in p.format(hub.snapshot())
    assert "loss 1.25" in p.format(DRIVER_SNAP)  # without one, the total loss as before
