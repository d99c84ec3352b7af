"""The one place that knows the process layout.

    N collectors (E envs each)  ──sequences──►  S replay shards  ◄──samples── learner
    M reanalyzers ◄─samples / write-backs─►  replay                 │ one ray.put per version
    collectors, reanalyzers, evaluator  ◄──pull at segment boundaries── weight broker

Ray is embedded (a local instance) unless `--address` / `ray.address` names a cluster.
Every role's resources come from the config, so a GPU learner with CPU collectors, or
collectors pinned to tagged nodes, is a config change.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.calls import LocalHandle, get, kill
from wmdist.runtime.named import start_named
from wmdist.runtime.resources import BROKER_CPUS, check_fits
from wmdist.runtime.table import Context, Role, RoleResources, by_name, run_roles



def start_ray(cfg: RunConfig) -> None:
    """Join `ray.address`, or start an embedded local instance sized by the config."""
    import ray

    if ray.is_initialized():
        return
    if cfg.ray.address:
        ray.init(address=cfg.ray.address, log_to_driver=True, configure_logging=False)
        _ray_notices_to_log()
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
    _ray_notices_to_log()
    _log_where_ray_logs()


def _ray_notices_to_log() -> None:
    """Ray's notices to the driver ("(raylet) A worker died...", "Task ... will be retried")
    go to the run's wmdist.log instead of the console: they are paragraphs, and the driver
    already reports each restart on its progress line (`restarts learner 1`). A private hook
    (the function Ray's error listener prints with); without it the notices stay on the console."""
    import logging

    try:
        import ray._private.worker as ray_worker

        show = ray_worker.print_to_stdstream
    except (ImportError, AttributeError):
        return
    if getattr(show, "wmdist_to_log", False):
        return

    def to_log(data: dict, ignore_prefix: bool) -> None:
        if data.get("pid") != "raylet":
            show(data, ignore_prefix)
            return
        for line in data.get("lines", []):
            logging.getLogger("wmdist").warning("Ray: %s", line)

    to_log.wmdist_to_log = True  # type: ignore[attr-defined]
    ray_worker.print_to_stdstream = to_log


def _log_where_ray_logs() -> None:
    import logging

    try:
        from ray._private.worker import _global_node

        logging.getLogger("wmdist").info("Ray's process logs: %s", _global_node.get_logs_dir_path())
    except Exception:  # noqa: BLE001 - a private API: the note is a convenience
        pass


@dataclass
class Topology:
    """The run's actors, by role name (in table order), and the services they share."""

    cfg: RunConfig
    spec: EnvSpec
    run_dir: Path
    replay: Any
    broker: Any
    roles: tuple[Role, ...] = ()
    actors: dict[str, list[Any]] = field(default_factory=dict)
    local: bool = False  # the Ray-free local runner: every actor is a LocalHandle

    def role(self, name: str) -> Role:
        return by_name(self.roles)[name]

    @property
    def learner(self) -> Any:
        return self.actors["learner"][0]

    @property
    def collectors(self) -> list[Any]:
        return self.actors.get("collector", [])

    @property
    def reanalyzers(self) -> list[Any]:
        return self.actors.get("reanalyzer", [])

    @property
    def evaluator(self) -> Any:
        ev = self.actors.get("evaluator", [])
        return ev[0] if ev else None

    def replace(self, name: str, i: int) -> Any:
        """A new actor i of role `name` in place of one whose process died and that Ray will not
        bring back (the learner: `max_restarts` 0, since a restart would lose its state anyway)."""
        role = self.role(name)
        try:
            kill(self.actors[name][i])  # dead already; its resources must be free for the new one
        except Exception:  # noqa: BLE001
            pass
        ctx = Context(self.cfg, self.spec, self.replay, self.broker, self.actors)
        self.actors[name][i] = _start(role, ctx, i, role.resources_of(self.cfg), self.local)
        return self.actors[name][i]

    def shutdown(self) -> None:
        try:
            get(self.learner.close.remote(), timeout=10)
        except Exception:  # noqa: BLE001 - shutting down anyway
            pass
        try:
            self.replay.close()
        except Exception:  # noqa: BLE001
            pass
        for actor in [*(a for group in self.actors.values() for a in group), self.broker]:
            try:
                kill(actor)
            except Exception:  # noqa: BLE001
                pass
        if self.local:
            return
        # kills are asynchronous: give the processes a moment to hand their CPUs back, so a
        # next run in the same Ray instance (tests, notebooks) is not left pending
        import time

        import ray

        deadline = time.monotonic() + 5.0  # on a shared cluster other jobs may keep CPUs: bounded
        while time.monotonic() < deadline:
            if ray.available_resources().get("CPU", 0.0) >= ray.cluster_resources().get("CPU", 0.0) - 1e-6:
                break
            time.sleep(0.1)


def build(cfg: RunConfig, spec: EnvSpec, run_dir: Path, fields: dict, local: bool = False) -> Topology:
    """Create every actor of the table (after checking the cluster can hold them all).

    Replay comes first (every role writes to or reads from it), then the weight broker, then
    the roles in table order. With `local` every actor is a plain object in this process."""
    from wmdist.runtime.replay_client import create_replay
    from wmdist.runtime.roles.weights import WeightBroker

    table = run_roles(cfg)
    if local:
        # one thread runs every role: a collector must not wait on a limiter only the learner frees
        cfg = dataclasses.replace(cfg, actors=dataclasses.replace(cfg.actors, insert_timeout=0.0))
    else:
        import ray

        check_fits(cfg, ray.cluster_resources(), table)
    replay = create_replay(cfg.replay, fields, str(run_dir), cfg.run.name, local=local)
    if local:
        broker: Any = LocalHandle(WeightBroker())
    else:
        import ray
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        # the broker lives on the driver's node: losing any other node must not lose the weights' route
        here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
        # a broker whose process died is restarted, its calls retried there: it holds only the newest
        # snapshot's refs, and the learner's next publish (every learner.publish_every updates) refills it
        # (named: it goes into restartable actors' constructors, where a handle would not cross, named.py)
        broker = start_named(ray.remote(WeightBroker), "broker", 0, (), num_cpus=BROKER_CPUS, scheduling_strategy=here,
                             max_restarts=-1, max_task_retries=-1)
    topo = Topology(cfg, spec, run_dir, replay, broker, table, local=local)
    ctx = Context(cfg, spec, replay, broker, topo.actors)
    try:
        # roles that serve the learner come first: the learner is handed their actors (ctx.actors)
        for role in sorted(table, key=lambda r: not r.serves_learner):
            if role.owner != "topology":
                continue  # replay's shards and limiter: created with replay above
            res = role.resources_of(cfg)
            topo.actors[role.name] = [_start(role, ctx, i, res, local) for i in range(role.count(cfg))]
            if role.ready_first:
                get([a.ping.remote() for a in topo.actors[role.name]])
    except BaseException:
        topo.shutdown()
        raise
    return topo


def _start(role: Role, ctx: Context, i: int, res: RoleResources, local: bool) -> Any:
    """Actor i of `role`: a Ray actor with the entry's resources and restart policy, or (local)
    the object itself behind a LocalHandle."""
    cls, args = role.actor(), role.args(ctx, i, res)
    if local:
        return LocalHandle(cls(*args))
    import ray

    restarts = role.max_restarts(ctx.cfg)
    opts = dict(res.options(), max_restarts=restarts, **role.options)
    if restarts != 0:
        opts.setdefault("max_task_retries", 0)  # a failed call is the driver's to re-issue
    return ray.remote(cls).options(**opts).remote(*args)
