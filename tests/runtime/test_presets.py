"""A short run of one preset per algorithm family (`RAY_PRESETS`) on the 2-CPU local Ray
instance: the whole runtime with the real algorithm, and the (world-)model loss falls. Every
preset also takes a first update under the local runner (test_local_runner.py).

"Falls" is judged on fixed data: after the run, the learner's state from before its first
update and its final state each score the same batches drawn from the run's replay. The
per-slice losses the learner reports are each on a fresh small batch of a replay that
keeps changing (a new episode can raise the loss of a model that is learning), so a trend
in them can fail on a learning model: it did once in CI (V2: 22, 17, 25, 20, 16, 16, 29).
"""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

from wmdist.config.loader import load_config
from wmdist.runtime.driver import LEARNER_SLICE_SECONDS, Counters, Driver
from wmdist.runtime.roles.setup import build_algorithm
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

CONFIGS = Path(__file__).parents[2] / "configs"
PRESETS = sorted(p.name for p in CONFIGS.glob("*.yaml") if p.name != "base.yaml")

# Keep each run short: small warm-up, small batches, no evaluator, no metrics server, one collector.
SHORT = ["eval.every_seconds=0", "metrics.enabled=false", "checkpoint.every_seconds=0", "actors.num=1",
         "run.log_every_seconds=0.5", "run.max_env_steps=0", "run.max_minutes=3", "actors.segment_steps=10"]
# Per preset: the budget of the short run. The paper-sized Atari network (16 residual blocks of 256
# channels, 50 simulations) takes seconds per env step on one CPU, so its smoke run shrinks the tower
# and the search (the in-process test checks the full network's shapes); Dreamer runs use small
# batches so a handful of updates fit. Smoke presets have to run; the others' loss must fall.
BUDGET = {
    "muzero_atari.yaml": ["run.max_env_steps=300", "replay.min_size=60", "actors.envs_per_actor=2",
                          "learner.batch_size=4", "algo.conv_channels=8", "algo.conv_blocks=1", "algo.hidden=[16]",
                          "algo.search.num_simulations=2", "algo.value_support=20", "algo.reward_support=5"],
    "dreamerv3_dmc_pixels.yaml": ["run.max_updates=4", "replay.min_size=60", "learner.batch_size=2",
                                  "replay.seq_len=16", "actors.envs_per_actor=2"],
    # the authors' Atari network (64 channels, LSTM 512, projector 1024) shrunk like muzero_atari's
    "efficientzero_atari.yaml": ["run.max_env_steps=200", "replay.min_size=60", "learner.batch_size=4",
                                 "algo.conv_channels=8", "algo.hidden=[16]", "algo.search.num_simulations=2",
                                 "algo.value_support=20", "algo.reward_support=5", "algo.lstm_hidden=16",
                                 "algo.proj_hidden=16", "algo.proj_dim=16", "algo.pred_hidden=8",
                                 "reanalyze.batch_size=2"],
    # PlaNet plans every action with CEM: a small planner keeps the collector's steps cheap
    "planet_dmc_cartpole_swingup.yaml": ["run.max_updates=25", "replay.min_size=200", "actors.warmup_random_steps=200",
                                         "learner.batch_size=8", "replay.seq_len=16", "replay.samples_per_insert=40",
                                         "replay.error_buffer=40", "algo.planner.candidates=20", "algo.planner.top_k=4",
                                         "algo.planner.iterations=2"],
    "planet_dmc_cartpole_swingup_pixels.yaml": ["run.max_updates=4", "replay.min_size=60", "actors.warmup_random_steps=60",
                                                "learner.batch_size=2", "replay.seq_len=16", "algo.planner.candidates=20",
                                                "algo.planner.top_k=4", "algo.planner.iterations=2"],
}
# A high train ratio keeps the replayed data nearly fixed over the short run, so a falling loss
# means the model learns rather than that the data got easier (or harder: a falling pole).
DREAMER = ["run.max_updates=25", "replay.min_size=200", "learner.batch_size=8", "replay.seq_len=16",
           "replay.samples_per_insert=40", "replay.error_buffer=40"]
MUZERO = ["run.max_updates=40", "replay.min_size=300", "learner.batch_size=32"]
SMOKE = {"muzero_atari.yaml", "dreamerv3_dmc_pixels.yaml", "planet_dmc_cartpole_swingup_pixels.yaml"}
SMOKE.add("efficientzero_atari.yaml")
# MinAtar: the Breakout presets take the default budgets; the Asterix ones are the same settings on
# another game, so a smoke run each (small batches, a few updates) shows they start and train.
MINATAR_SMOKE = ["run.max_updates=6", "replay.min_size=200", "learner.batch_size=8", "actors.envs_per_actor=4"]
BUDGET.update({"dreamerv3_minatar_breakout.yaml": [*DREAMER, "actors.warmup_random_steps=200"],
               "muzero_minatar_asterix.yaml": MINATAR_SMOKE,
               "dreamerv3_minatar_asterix.yaml": [*MINATAR_SMOKE, "replay.seq_len=16", "actors.warmup_random_steps=200"]})
SMOKE |= {"muzero_minatar_asterix.yaml", "dreamerv3_minatar_asterix.yaml"}
# World Models: two updates of V, two of M, then CMA-ES generations scored by the evaluation pool (a smoke run)
WORLDMODELS = ["run.max_updates=6", "replay.min_size=60", "learner.batch_size=2", "replay.seq_len=8", "replay.overlap=2",
               "actors.envs_per_actor=2", "algo.vae_updates=2", "algo.rnn_updates=2", "algo.popsize=4", "algo.rollouts=1",
               "algo.vae_frames=8", "algo.dream_max_steps=50", "algo.real_max_steps=20"]
BUDGET.update({"worldmodels_carracing.yaml": WORLDMODELS, "worldmodels_doom_takecover.yaml": WORLDMODELS})
SMOKE |= {"worldmodels_carracing.yaml", "worldmodels_doom_takecover.yaml"}
# JEPA: reward-free random data; small windows and batches, a high train ratio (the loss includes SIGReg)
BUDGET["jepa_nav_tworooms.yaml"] = ["run.max_updates=25", "replay.min_size=200", "learner.batch_size=8",
                                    "replay.samples_per_insert=40", "replay.error_buffer=40", "replay.capacity_steps=4000"]
SCORE_BATCHES = 6  # fixed batches each state is scored on

# The Ray runs: one preset per algorithm family and role mix (the suite's 15-minute budget on 2 cores
# cannot hold a Ray run of all of them). Every preset, these included, takes its first update under the
# local runner (tests/runtime/test_local_runner.py), which runs the same collector, replay and learner code.
RAY_PRESETS = sorted({
    "muzero_cartpole.yaml",             # MuZero, the make-run job
    "efficientzero_cartpole.yaml",      # MuZero family + a reanalyzer role (off-policy-corrected targets)
    "dreamerv3_cartpole.yaml",          # Dreamer
    "planet_dmc_cartpole_swingup.yaml",  # PlaNet: CEM planning in the collector, dm_control
} & set(PRESETS))
# Covered on Ray elsewhere: every built-in role with the fake algorithm (tests/runtime/test_runtime.py),
# World Models' pool role (tests/algos/worldmodels/test_cmaes_pool.py), a role an algorithm adds
# (tests/runtime/test_roles_table.py); two-player self-play in process (tests/algos/muzero/test_tictactoe.py).


def _budget(preset: str) -> list[str]:
    return BUDGET.get(preset, DREAMER if preset.startswith("dreamer") else MUZERO)


def _loss_key(algo_name: str) -> str:
    return "model_loss" if algo_name in ("dreamer", "planet") else "loss"


def _fixed_batches(topo, batch_size: int) -> list[dict]:
    """SCORE_BATCHES batches of the run's replay (outside the rate limiter), as the learner gets them."""
    out = []
    for _ in range(SCORE_BATCHES):
        sample = topo.replay.sample(batch_size, timeout=10.0, limited=False)
        assert sample is not None, "replay is empty after the run"
        out.append(dict(sample.data, mask=sample.mask, is_weight=sample.is_weight))
    return out


def _score(cfg, spec, state: dict, batches: list[dict], key: str) -> float:
    """Mean `key` over `batches`, each computed by a learner restored to `state`: an update's
    metrics are its loss before it steps, and the step is thrown away with the copy."""
    learner = build_algorithm(cfg, spec, cfg.run.seed).make_learner("cpu")
    losses = []
    for batch in batches:
        learner.load_state_dict(copy.deepcopy(state))
        losses.append(float(learner.update(batch).metrics[key]))
    return float(np.mean(losses))


class _LossTraceDriver(Driver):
    """Learner slices of at most a few updates, each slice's loss recorded: the loss is seen many
    times even when the learner is fast enough to run the whole budget inside one time slice."""

    def __init__(self, *args, key: str, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.key, self.losses_seen = key, []

    def _issue(self, kind: str, i: int) -> None:
        if kind != "learner":
            return super()._issue(kind, i)
        cap = self.c.updates + 4
        if self.cfg.run.max_updates:
            cap = min(cap, self.cfg.run.max_updates)
        self.inflight[self.topo.learner.train_for.remote(LEARNER_SLICE_SECONDS, cap)] = (kind, i)

    def _handle(self, kind: str, i: int, res: dict) -> None:
        super()._handle(kind, i, res)
        if kind == "learner" and self.key in res.get("losses", {}):
            self.losses_seen.append(float(res["losses"][self.key]))


@pytest.mark.parametrize("preset", RAY_PRESETS)
def test_preset_runs_and_its_loss_falls(ray_session, tmp_path, preset):
    cfg = load_config(CONFIGS / preset, [f"run.dir={tmp_path}", *SHORT, *_budget(preset)])
    spec = env_spec_or_error(cfg)
    topo = build(cfg, spec, tmp_path, build_algorithm(cfg, spec, 0).step_fields())
    driver = _LossTraceDriver(topo, Counters(), key=_loss_key(cfg.algo_name))
    try:
        before = ray_session.get(topo.learner.state.remote())["learner"]  # version 0, no update yet
        result = driver.run()
        after = ray_session.get(topo.learner.state.remote())["learner"]
        batches = _fixed_batches(topo, cfg.learner.batch_size)
    finally:
        topo.shutdown()
    losses = driver.losses_seen
    assert result.status == "done", result.message
    assert result.counters.updates >= 2 and result.counters.env_steps > 0
    if preset == "muzero_atari.yaml":
        assert result.counters.env_steps >= 300  # a few hundred steps on Pong
    if preset in SMOKE:
        assert all(np.isfinite(losses)), losses
        return
    assert len(losses) >= 2, losses
    start, end = (_score(cfg, spec, state, batches, driver.key) for state in (before, after))
    assert end < start, f"{preset}: {driver.key} on fixed batches did not fall: {start:.4g} -> {end:.4g} (slices: {losses})"


@pytest.mark.parametrize("preset", PRESETS)
def test_preset_fits_the_default_two_cpu_machine(preset):
    """`wmdist train configs/X.yaml` on a 2-core laptop must not be refused for CPUs."""
    from wmdist.runtime.resources import check_fits

    check_fits(load_config(str(CONFIGS / preset)), {"CPU": 2.0})
