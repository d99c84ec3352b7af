"""The actor-learner runtime on a real 2-CPU local Ray instance, with the fake algorithm."""
from __future__ import annotations

import os
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from wmdist.config.errors import ConfigError
from wmdist.config.loader import dump_yaml, load_config
from wmdist.runtime import checkpoint as ck
from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.roles.setup import build_algorithm
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

CFG = str(Path(__file__).parent / "fake.yaml")


def _topology(tmp_path, *overrides, local: bool = False):
    cfg = load_config(CFG, [f"run.dir={tmp_path}", *overrides, *(["ray.local=true"] if local else [])])
    spec = env_spec_or_error(cfg)
    fields = build_algorithm(cfg, spec, 0).step_fields()
    run_dir = tmp_path / "run"
    run_dir.mkdir(exist_ok=True)
    (run_dir / "config.yaml").write_text(dump_yaml(cfg))
    return build(cfg, spec, run_dir, fields, local=local)


def _complete_sequences_only(sample) -> None:
    """Every sampled window is a prefix of real steps; a short one ends its episode."""
    mask = sample.mask.astype(bool)  # [B, T]
    for row, m in enumerate(mask):
        n = int(m.sum())
        assert n > 0 and m[:n].all() and not m[n:].any()
        if n < mask.shape[1]:
            assert sample.data["last"][row, n - 1]


def _thread_nice_levels(pid: int) -> dict[int, int]:
    """Thread id -> nice level of each thread of process `pid` (field 19 of /proc/PID/task/TID/stat)."""
    levels = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            stat = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
        except FileNotFoundError:  # a thread that exited while we looked
            continue
        levels[int(tid)] = int(stat.rsplit(")", 1)[1].split()[16])  # fields after the command: state 3rd, nice 19th
    return levels


class _EveryRoleDriver(Driver):
    """Runs past its update budget until every role has reported once (a loaded machine can
    finish 80 updates before the first reanalyze job returns), for at most two minutes."""

    def _budget_done(self) -> bool:
        c = self.c
        every_role = c.episodes > 0 and c.reanalyzed > 0 and c.eval_episodes > 0
        return super()._budget_done() and (every_role or self.elapsed() > 120)


def test_full_topology_versions_reach_collectors_and_actions_follow_weights(ray_session, tmp_path):
    """Every role runs; versions advance and reach every collector; actions follow weights; the
    metrics endpoint serves every declared metric."""
    from wmdist.telemetry.metrics import METRICS
    from wmdist.telemetry.publish import Telemetry

    ray = ray_session
    # 80 updates end it; the minutes are a backstop (fake.yaml's 0.5 ended a loaded CI run at 7 updates)
    topo = _topology(tmp_path, "reanalyze.num=1", "eval.every_seconds=1", "run.max_updates=80", "replay.shards=2",
                     "metrics.enabled=true", "run.max_minutes=3", "reanalyze.nice=5")
    tele = Telemetry(topo.cfg, topo.run_dir, open(os.devnull, "w"))
    try:
        driver = _EveryRoleDriver(topo, Counters(), on_tick=tele.update)
        result = driver.run()
        assert result.status == "done", result.message
        body = urllib.request.urlopen(f"http://127.0.0.1:{tele.hub.port}/metrics", timeout=10).read().decode()
        missing = [name for name in METRICS if f"\n{name}" not in body]
        assert not missing, missing
        c = result.counters
        assert c.updates >= 80 and c.version >= 80 // 5
        assert c.env_steps > 0 and c.episodes > 0 and c.reanalyzed > 0 and c.eval_episodes > 0
        # the train lines say what the reanalyzers did against the learner's samples, and each role's busy time
        last = driver._work_counts()
        assert 0 < last["reanalyzed"] == c.reanalyzed and 0 < last["sampled_sequences"], last
        assert last["busy/learner"] > 0 and last["busy/collector"] > 0, last
        # the reanalyzer works at reanalyze.nice above the learner, on every thread of its process
        # (base: the level of the thread a collector runs its calls on; Ray may have started some of a worker's
        # threads before it set the workers' own level, so a process's threads can differ)
        col_pid = ray.get(topo.collectors[0].run_segment.remote())["pid"]
        base = _thread_nice_levels(col_pid)[col_pid]
        levels = set(_thread_nice_levels(ray.get(topo.reanalyzers[0].run_job.remote())["pid"]).values())
        assert levels == {min(19, base + 5)}, (levels, base)
        # every collector pulls the newest version at its next segment boundary
        for col in topo.collectors:
            ray.get(col.run_segment.remote())
            assert ray.get(col.current_version.remote()) == c.version
        # actions follow the published weights: all-right, then all-left
        obs = np.abs(np.random.default_rng(0).normal(size=(16, 4))).astype(np.float32) + 0.1  # [16, 4] > 0
        for version, favoured in ((10_000, 1), (10_001, 0)):
            w = np.zeros((4, 2), np.float32)
            w[:, favoured] = 1.0  # positive observations: the favoured column's logit wins
            ref = ray.put({"w": w})
            ray.get(topo.broker.publish.remote(version, [ref]))
            for col in topo.collectors:
                ray.get(col.run_segment.remote())
                assert ray.get(col.current_version.remote()) == version
                acts = ray.get(col.probe_actions.remote(obs))
                assert (acts == favoured).all()
    finally:
        tele.close()
        topo.shutdown()


class _RestartDriver(Driver):
    """Runs past its time budget until `restarts` collector restarts were seen (for at most 240 s, so
    a restart that never comes fails the assertion, not the 300 s test timeout): on a loaded
    machine start-up alone can outlast a short budget."""

    def __init__(self, *args, restarts: int = 1, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.restarts_wanted = restarts

    def _budget_done(self) -> bool:
        restarted = self.c.restarts.get("collector", 0) >= self.restarts_wanted
        return (restarted and super()._budget_done()) or self.elapsed() > 240


def _kill_later(ray, actor, ready, record: dict) -> threading.Thread:
    """A thread that kills `actor` (Ray restarts it) once `ready()` holds (at most 120 s on)."""

    def kill() -> None:
        deadline = time.monotonic() + 120
        while not ready() and time.monotonic() < deadline:
            time.sleep(0.05)
        ray.kill(actor, no_restart=False)
        record["killed"] = True

    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread


def test_killed_collectors_restart_with_current_weights(ray_session, tmp_path):
    """One run, both faults: collector 0 killed during start-up (no call fails: its queued calls
    run in the replacement), collector 1 killed mid-run (its call fails). Each comes back with
    current weights, and both restarts are counted."""
    ray = ray_session
    topo = _topology(tmp_path, "run.max_minutes=0.15", "actors.num=2")
    counters = Counters()
    killed = {"starting": {"version": ray.get(topo.broker.current_version.remote())}, "stepping": {}}

    def stepping() -> bool:
        if counters.env_steps == 0:  # a fixed delay could fall inside start-up
            return False
        killed["stepping"]["version"] = ray.get(topo.broker.current_version.remote())
        return True

    timers = [_kill_later(ray, topo.collectors[0], lambda: True, killed["starting"]),
              _kill_later(ray, topo.collectors[1], stepping, killed["stepping"])]
    try:
        result = _RestartDriver(topo, counters, restarts=2).run()
        for t in timers:
            t.join()
        assert all(k.get("killed") for k in killed.values())
        assert result.status == "done", result.message
        assert result.counters.restarts["collector"] >= 2
        assert result.counters.updates > 0
        # back with weights at least as new as when each died, and stepping again
        for victim, when in zip(topo.collectors, ("starting", "stepping")):
            assert ray.get(victim.current_version.remote(), timeout=60) >= killed[when]["version"], when
            stats = ray.get(victim.run_segment.remote())
            assert stats["env_steps"] > 0 or stats["limiter_blocked"], when
        sample = topo.replay.sample(64, timeout=5)
        assert sample is not None
        _complete_sequences_only(sample)
    finally:
        topo.shutdown()


def test_collector_with_no_restarts_left_ends_the_run_with_one_line(ray_session, tmp_path):
    topo = _topology(tmp_path, "run.max_minutes=2", "actors.max_restarts=0")
    counters = Counters()
    timer = _kill_later(ray_session, topo.collectors[0], lambda: counters.env_steps > 0, {})
    try:
        result = Driver(topo, counters).run()
        timer.join()
        assert result.status == "error", (result.status, result.message)
        assert "collector 0 died and its restarts are used up" in result.message
        assert "\n" not in result.message
        assert counters.elapsed_seconds < 110  # it stopped, well before the 2-minute budget
    finally:
        topo.shutdown()


def test_resume_restores_counters_weights_optimizer_and_replay(ray_session, tmp_path):
    ray = ray_session
    topo = _topology(tmp_path, "run.max_updates=40", "checkpoint.every_seconds=0", "replay.shards=2")
    try:
        first = Driver(topo, Counters()).run()
        assert first.status == "done"
        state = ray.get(topo.learner.state.remote())
    finally:
        topo.shutdown()
    ckpt = ck.latest_checkpoint(tmp_path / "run")
    assert ckpt is not None
    saved = ck.load_counters(ckpt)
    assert saved["updates"] == first.counters.updates and saved["env_steps"] == first.counters.env_steps

    topo2 = _topology(tmp_path, "run.max_updates=40", "replay.shards=2")
    try:
        ray.get(topo2.learner.load.remote(ck.load_learner_state(ckpt)))
        topo2.replay.restore(str(ckpt / "replay"))
        state2 = ray.get(topo2.learner.state.remote())
        assert state2["updates"] == state["updates"] and state2["version"] == state["version"]
        np.testing.assert_array_equal(state2["learner"]["w"].numpy(), state["learner"]["w"].numpy())
        m1 = state["learner"]["opt"]["optimizer"]["state"][0]["momentum_buffer"]
        m2 = state2["learner"]["opt"]["optimizer"]["state"][0]["momentum_buffer"]
        np.testing.assert_array_equal(m1.numpy(), m2.numpy())
        # replay holds exactly what was saved: saving it again gives identical stats and bytes
        resaved = tmp_path / "resaved"
        topo2.replay.save(str(resaved))
        for f in sorted(p for p in (ckpt / "replay").rglob("*") if p.is_file() and "limiter" not in p.name):
            assert (resaved / f.relative_to(ckpt / "replay")).read_bytes() == f.read_bytes(), f.name
        # the resumed version is what collectors now see
        assert ray.get(topo2.broker.current_version.remote()) == state["version"]
    finally:
        topo2.shutdown()


def test_train_ratio_held_within_ten_percent(ray_session, tmp_path):
    topo = _topology(tmp_path, "replay.samples_per_insert=2", "replay.error_buffer=8", "replay.min_size=32",
                     "run.max_minutes=0.2", "actors.num=1")
    try:
        Driver(topo, Counters()).run()
        st = topo.replay.stats()
        inserted, sampled = st["limiter_inserted"], st["limiter_sampled"]
        assert inserted > 50
        assert abs(sampled / inserted - 2.0) <= 0.2, (sampled, inserted)
    finally:
        topo.shutdown()


def test_more_collectors_gather_more_steps_with_a_slow_env(ray_session, tmp_path):
    rates = {}
    for n in (1, 3):
        topo = _topology(tmp_path, "env.id=gym:tests.runtime.slow_env:SlowCartPole-v0", f"actors.num={n}",
                         "actors.cpus=0.3", "run.max_minutes=0.08", "learner.cpus=0.2")
        try:
            ray_session.get([c.ping.remote() for c in topo.collectors])  # time steady state, not process start
            t0 = time.monotonic()
            res = Driver(topo, Counters()).run()
            rates[n] = res.counters.env_steps / (time.monotonic() - t0)
        finally:
            topo.shutdown()
    assert rates[3] > 1.8 * rates[1], rates


def test_config_needing_more_cpus_than_the_cluster_fails_before_any_actor(ray_session, tmp_path):
    ray = ray_session
    total = ray.cluster_resources()["CPU"]
    deadline = time.monotonic() + 20
    while ray.available_resources().get("CPU", 0.0) < total and time.monotonic() < deadline:
        time.sleep(0.2)  # earlier tests' actors are gone
    free_before = ray.available_resources().get("CPU", 0.0)
    with pytest.raises(ConfigError) as err:
        _topology(tmp_path, "actors.num=40", "actors.cpus=0.5")
    msg = str(err.value)
    assert "needs" in msg and "CPU" in msg and "\n" not in msg
    time.sleep(0.5)
    assert ray.available_resources().get("CPU", 0.0) == pytest.approx(free_before)  # nothing was started


def test_unknown_algorithm_fails_before_ray(tmp_path):
    with pytest.raises(ConfigError, match="unknown algorithm 'dreamr'"):
        load_config(CFG, ["algo.name=dreamr"])


def test_nan_guard_skips_then_stops_with_a_clear_message(tmp_path, capsys):
    """The guard is the learner's and the driver's (the local runner runs both as on Ray)."""
    from wmdist.runtime.train import train

    cfg = load_config(CFG, [f"run.dir={tmp_path}", "algo.nan_every=5", "learner.max_nan_streak=3",
                            "actors.num=1", "ray.local=true"])
    assert train(cfg=cfg) == 1
    err = capsys.readouterr().err
    assert "3 non-finite updates in a row" in err and "--resume" in err
    run_dir = next(tmp_path.iterdir())
    ckpt = ck.latest_checkpoint(run_dir)
    counters = ck.load_counters(ckpt)
    assert counters["nan_skips"] == 3 and counters["updates"] == 4  # updates 1-4 applied, then 3 skipped


def test_learner_failure_stops_the_run_naming_resume(ray_session, tmp_path, capsys):
    from wmdist.runtime.train import train

    cfg = load_config(CFG, [f"run.dir={tmp_path}", "algo.crash_at=3", "actors.num=1"])
    assert train(cfg=cfg) == 1
    err = capsys.readouterr().err
    assert "learner failed" in err and "simulated learner crash" in err
    # it failed before any checkpoint (checkpoint.every_seconds=0): the hint is the saved config,
    # not a --resume that would find nothing
    run_dir = next(tmp_path.iterdir())
    assert ck.latest_checkpoint(run_dir) is None
    assert f"start again with `wmdist train {run_dir / 'config.yaml'}`" in err
    assert len(err.strip().splitlines()) == 1


def test_collector_that_cannot_start_stops_the_run_with_the_cause(ray_session, tmp_path, capsys):
    from wmdist.runtime.train import train

    cfg = load_config(CFG, [f"run.dir={tmp_path}", "algo.policy_fails=true", "actors.num=1",
                            "run.max_minutes=2"])
    t0 = time.monotonic()
    assert train(cfg=cfg) == 1
    err = capsys.readouterr().err
    assert "could not start" in err and "ValueError: simulated policy construction failure" in err
    assert time.monotonic() - t0 < 60  # stopped at once, not after the time budget


def test_run_stops_once_the_eval_return_reaches_the_target(tmp_path):
    """The stop is the driver's (the local runner runs the same driver and evaluator)."""
    import io

    from wmdist.runtime.train import train

    cfg = load_config(CFG, [f"run.dir={tmp_path}", "run.stop_at_eval_return=-1000000", "eval.every_seconds=1",
                            "actors.num=1", "run.max_minutes=3", "run.max_env_steps=0", "ray.local=true"])
    t0 = time.monotonic()
    out = io.StringIO()
    assert train(cfg=cfg, out=out) == 0
    assert "reached -1e+06" in out.getvalue()
    assert time.monotonic() - t0 < 90  # long before the 3-minute budget


@pytest.mark.parametrize("sampler", ["uniform", "prioritized"])
def test_learner_writes_priorities_back_only_when_sampling_by_priority(ray_session, tmp_path, sampler):
    """Prioritized on Ray (the learner actor writes back to the shard actor); uniform, where
    nothing may be written, under the local runner (the same learner and shard code)."""
    from wmdist.runtime.calls import get

    topo = _topology(tmp_path, f"replay.sampler={sampler}", "replay.min_size=32", "run.max_updates=20",
                     "run.max_minutes=3", "actors.num=1", local=sampler == "uniform")
    try:
        result = Driver(topo, Counters()).run()
        assert result.counters.updates >= 20
        get(topo.replay.shards[0].save.remote(str(tmp_path / "shard.npz")))
        with np.load(tmp_path / "shard.npz") as saved:
            stamp, priority = saved["i_stamp"], saved["i_priority"]
        live = priority[stamp >= 0]  # occupied slots
        assert live.size > 0
        distinct = len(np.unique(live))
        if sampler == "uniform":  # never read, so never written back: every item keeps its insert priority
            assert distinct == 1, np.unique(live)
        else:  # the fake learner's priorities (per-sequence losses) replaced the initial ones
            assert distinct > 1
    finally:
        topo.shutdown()
