"""The table of roles: one entry per role, read by topology, the resource check, the driver
and telemetry; an algorithm's own role runs on Ray like the built-in ones."""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from wmdist.config.errors import ConfigError
from wmdist.config.loader import dump_yaml, load_config
from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.resources import check_fits, roles
from wmdist.runtime.roles.setup import build_algorithm
from wmdist.runtime.table import BUILTIN_NAMES, run_roles
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

CFG = str(Path(__file__).parent / "fake.yaml")
TOY = "algo.name=tests.runtime.toy_role:ToyAlgo"


def test_table_lists_every_builtin_role_once():
    assert BUILTIN_NAMES == ("replay", "limiter", "learner", "collector", "reanalyzer", "evaluator")
    cfg = load_config(CFG, ["reanalyze.num=3", "eval.every_env_steps=500", "replay.shards=2"])
    got = roles(cfg)
    assert got["collector"][1] == 2 and got["reanalyzer"][1] == 3 and got["evaluator"][1] == 1
    assert got["replay"][1] == 2 and got["replay"][0].cpus == pytest.approx(0.05)
    assert "evaluator" not in roles(load_config(CFG, []))  # eval by neither time nor steps: no evaluator


def test_an_algorithm_role_joins_the_table_and_the_resource_check():
    cfg = load_config(CFG, [TOY, "algo.toy_num=3", "algo.toy_cpus=0.5"])
    names = [r.name for r in run_roles(cfg)]
    assert names[-1] == "toy" and names[:-1] == list(BUILTIN_NAMES)
    assert roles(cfg)["toy"][1] == 3
    # 3 x 0.5 toy CPUs on top of the fake config's 0.95 do not fit 2 CPUs: named in the message
    with pytest.raises(ConfigError, match=r"toy 0\.5 x 3"):
        check_fits(cfg, {"CPU": 2.0})
    check_fits(cfg, {"CPU": 4.0})


def test_a_role_name_may_not_shadow_a_builtin():
    from wmdist.runtime.table import Role, RoleResources, table

    clash = Role("learner", object, lambda c: c.learner, lambda c: 1, lambda s: RoleResources(0.1))
    with pytest.raises(ValueError, match="clashes"):
        table(load_config(CFG, []), (clash,))


def test_toy_role_runs_on_ray_is_restarted_and_reported(ray_session, tmp_path):
    """The toy algorithm's own role: built by topology, kept busy by the driver, restarted by Ray
    after its process is killed (counted), and exported as role="toy" metrics."""
    from wmdist.telemetry.metrics import MetricsHub
    from wmdist.telemetry.publish import publish

    ray = ray_session
    cfg = load_config(CFG, [f"run.dir={tmp_path}", TOY, "run.max_minutes=0", "run.max_updates=0"])
    spec = env_spec_or_error(cfg)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(dump_yaml(cfg))
    topo = build(cfg, spec, run_dir, build_algorithm(cfg, spec, 0).step_fields())
    try:
        toys = topo.actors["toy"]
        assert len(toys) == 2
        driver = Driver(topo, Counters())
        import threading

        th = threading.Thread(target=driver.run, daemon=True)
        th.start()
        deadline = time.monotonic() + 60
        while getattr(driver, "toy_calls", 0) < 5 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert getattr(driver, "toy_calls", 0) >= 5, "the driver never kept the toy role busy"
        os.kill(ray.get(toys[0].pid.remote()), 9)
        while driver.c.restarts.get("toy", 0) < 1 and time.monotonic() < deadline:
            time.sleep(0.1)
        driver.request_stop()
        th.join(60)
        assert driver.c.restarts.get("toy", 0) >= 1, driver.c.restarts
        assert driver.c.busy.get("toy", 0.0) > 0
        hub = MetricsHub()
        publish(hub, driver.tick())
        snap = hub.snapshot()
        assert snap["wmdist_busy_seconds_total{role=toy}"] > 0
        assert snap["wmdist_actor_restarts_total{role=toy}"] >= 1
    finally:
        topo.shutdown()


def test_every_metric_a_role_reports_is_declared():
    from wmdist.telemetry.metrics import METRICS
    from wmdist.runtime.table import BUILTIN

    for role in BUILTIN:
        for name in role.metrics:
            assert name in METRICS, (role.name, name)
