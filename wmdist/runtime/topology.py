"""The one place that knows the process layout.

    N collectors (E envs each)  ──sequences──►  S replay shards  ◄──samples── learner
    M reanalyzers ◄─samples / write-backs─►  replay                 │ one ray.put per version
    collectors, reanalyzers, evaluator  ◄──pull at segment boundaries── weight broker

Ray is embedded (a local instance) unless `--address` / `ray.address` names a cluster.
Every role's resources come from the config, so a GPU learner with CPU collectors, or
collectors pinned to tagged nodes, is a config change.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.resources import BROKER_CPUS, check_fits, roles



def start_ray(cfg: RunConfig) -> None:
    """Join `ray.address`, or start an embedded local instance sized by the config."""
    import ray

    if ray.is_initialized():
        return
    if cfg.ray.address:
        ray.init(address=cfg.ray.address, log_to_driver=True, configure_logging=False)
        return
    kwargs: dict[str, Any] = {
        "address": "local",  # a fresh embedded instance, never someone else's running cluster
        "num_cpus": cfg.ray.num_cpus or os.cpu_count() or 1,
        "include_dashboard": False,
        "object_store_memory": cfg.ray.object_store_mb * 1024 * 1024,
        "configure_logging": False,
        # workers' output (a failing actor's traceback) stays in Ray's log folder, named in the
        # run's wmdist.log; the console gets the driver's one-line summary
        "log_to_driver": False,
    }
    if cfg.ray.num_gpus >= 0:
        kwargs["num_gpus"] = cfg.ray.num_gpus
    # The raylet reads this when it starts and applies it to every worker it spawns.
    os.environ["RAY_worker_niceness"] = str(cfg.ray.worker_niceness)
    ray.init(**kwargs)
    _log_where_ray_logs()


def _log_where_ray_logs() -> None:
    import logging

    try:
        from ray._private.worker import _global_node

        logging.getLogger("wmdist").info("Ray's process logs: %s", _global_node.get_logs_dir_path())
    except Exception:  # noqa: BLE001 - a private API: the note is a convenience
        pass


@dataclass
class Topology:
    cfg: RunConfig
    spec: EnvSpec
    run_dir: Path
    replay: Any
    broker: Any
    learner: Any
    collectors: list[Any] = field(default_factory=list)
    reanalyzers: list[Any] = field(default_factory=list)
    evaluator: Any = None

    def shutdown(self) -> None:
        import ray

        try:
            ray.get(self.learner.close.remote(), timeout=10)
        except Exception:  # noqa: BLE001 - shutting down anyway
            pass
        try:
            self.replay.close()
        except Exception:  # noqa: BLE001
            pass
        for actor in [*self.collectors, *self.reanalyzers, self.evaluator, self.learner, self.broker]:
            if actor is not None:
                try:
                    ray.kill(actor, no_restart=True)
                except Exception:  # noqa: BLE001
                    pass
        # kills are asynchronous: give the processes a moment to hand their CPUs back, so a
        # next run in the same Ray instance (tests, notebooks) is not left pending
        import time

        deadline = time.monotonic() + 5.0  # on a shared cluster other jobs may keep CPUs: bounded
        while time.monotonic() < deadline:
            if ray.available_resources().get("CPU", 0.0) >= ray.cluster_resources().get("CPU", 0.0) - 1e-6:
                break
            time.sleep(0.1)


def build(cfg: RunConfig, spec: EnvSpec, run_dir: Path, fields: dict) -> Topology:
    """Create every actor (after checking the cluster can hold them all)."""
    import ray

    from wmdist.runtime.roles.collector import Collector
    from wmdist.runtime.roles.evaluator import EvaluatorRole
    from wmdist.runtime.roles.learner import LearnerRole
    from wmdist.runtime.roles.reanalyzer import ReanalyzerRole
    from wmdist.runtime.replay_client import create_replay
    from wmdist.runtime.roles.weights import WeightBroker

    check_fits(cfg, ray.cluster_resources())
    res = roles(cfg)
    replay = create_replay(cfg.replay, fields, str(run_dir), cfg.run.name)
    # the broker lives on the driver's node: losing any other node must not lose the weights' route
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
    broker = ray.remote(WeightBroker).options(num_cpus=BROKER_CPUS, scheduling_strategy=here).remote()
    lres = res["learner"][0]
    learner = ray.remote(LearnerRole).options(**lres.options(), max_restarts=0, max_concurrency=1).remote(
        cfg, spec, replay, broker, lres.threads)
    topo = Topology(cfg, spec, run_dir, replay, broker, learner)
    ray.get(learner.ping.remote())  # version 0 is published before anyone acts

    cres = res["collector"][0]
    restart = dict(max_restarts=cfg.actors.max_restarts, max_task_retries=0)
    topo.collectors = [
        ray.remote(Collector).options(**cres.options(), **restart).remote(cfg, spec, i, replay, broker, cres.threads)
        for i in range(cfg.actors.num)
    ]
    rres = res["reanalyzer"][0]
    topo.reanalyzers = [
        ray.remote(ReanalyzerRole).options(**rres.options(), max_restarts=-1, max_task_retries=0).remote(
            cfg, spec, i, replay, broker, rres.threads)
        for i in range(cfg.reanalyze.num)
    ]
    if "evaluator" in res:
        eres = res["evaluator"][0]
        topo.evaluator = ray.remote(EvaluatorRole).options(**eres.options(), max_restarts=-1).remote(
            cfg, spec, broker, eres.threads)
    return topo
