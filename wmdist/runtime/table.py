"""The table of roles: every kind of actor a run has, described once.

Each `Role` says which class its actors run, how many there are and what each asks Ray for
(read from the role's config section), its restart policy, the call the driver issues and
how the answer is folded into the run's counters. Topology builds the actors from this
table, the resource check sums it, the driver dispatches on it, telemetry labels its
metrics with its names, and the cluster files' custom resources are checked against the
sections it reads. An algorithm adds a role by returning more entries from
`Algorithm.extra_roles()`; nothing in the runtime changes.

No Ray import here: algorithms (which never import Ray) may declare roles.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

from wmdist.config.schema import RunConfig

if TYPE_CHECKING:  # pragma: no cover
    from wmdist.envs.spec import EnvSpec
    from wmdist.runtime.driver import Driver


@dataclass(frozen=True)
class RoleResources:
    """What one actor of a role asks Ray for."""

    cpus: float
    gpus: float = 0.0
    custom: dict = field(default_factory=dict)

    def options(self) -> dict:
        opts: dict = {"num_cpus": self.cpus, "num_gpus": self.gpus}
        if self.custom:
            opts["resources"] = dict(self.custom)
        return opts

    @property
    def threads(self) -> int:
        """torch threads for this share of the machine (at least one)."""
        return max(1, math.floor(self.cpus + 1e-9))


@dataclass
class Context:
    """What a role's constructor may need; `actors` fills in table order, so a role can be
    handed the actors of the roles listed before it."""

    cfg: RunConfig
    spec: "EnvSpec"
    replay: Any
    broker: Any
    actors: dict[str, list[Any]] = field(default_factory=dict)


# How the driver schedules a role's calls.
LOOP = "loop"  # re-issued as soon as the answer is in (collectors, the learner)
PACED = "paced"  # issued when the driver's pacing says it is due (reanalyzers: a share of samples)
PERIODIC = "periodic"  # one actor, every `eval.every_seconds` (the evaluator)
SERVICE = "service"  # no driver call: used by other roles (replay shards, an algorithm's pools)


@dataclass(frozen=True)
class Role:
    """One entry of the table."""

    name: str  # also the `role` label of its metrics and its key in `restarts` / `busy`
    actor: Callable[[], type]  # the actor class (imported late: roles import torch)
    section: Callable[[RunConfig], Any]  # the config section holding its resources
    count: Callable[[RunConfig], int]  # how many actors
    resources: Callable[[Any], RoleResources]  # one actor's share, read from `section`
    args: Callable[[Context, int, RoleResources], tuple] = lambda ctx, i, res: ()  # constructor args of actor i
    max_restarts: Callable[[RunConfig], int] = lambda cfg: -1  # Ray's policy: -1 forever, 0 never
    schedule: str = LOOP
    call: Callable[[Any, "Driver"], Any] | None = None  # issue one call on an actor; returns its ref
    handle: Callable[["Driver", int, dict], None] | None = None  # fold one answer into the driver's state
    fatal: bool = False  # a failed call ends the run (the learner), unless its process died: `Driver._restart_learner`
    drain: bool = True  # the driver waits for its in-flight call at the end (its data lands)
    options: dict = field(default_factory=dict)  # more actor options (max_concurrency)
    owner: str = "topology"  # who creates its actors: "topology", or "replay" (create_replay)
    ready_first: bool = False  # its actors answer a ping before later roles start (the learner
    #                            publishes weight version 0 before anyone acts)
    metrics: tuple[str, ...] = ("wmdist_busy_seconds_total", "wmdist_actor_restarts_total")
    serves_learner: bool = False  # built before the learner, whose Learner gets its handles
    #                               (`Learner.use_services`): an algorithm's evaluation pool

    def resources_of(self, cfg: RunConfig) -> RoleResources:
        return self.resources(self.section(cfg))


# -- answers ------------------------------------------------------------------------------
def answer_busy(d: "Driver", role: str, res: dict) -> None:
    """Every role's answer may carry the seconds it worked."""
    d.c.busy[role] = d.c.busy.get(role, 0.0) + float(res.get("busy_seconds", 0.0))


def _collector_answer(d: "Driver", i: int, res: dict) -> None:
    c = d.c
    c.env_steps += int(res["env_steps"])
    c.episodes += len(res["episodes"])
    answer_busy(d, "collector", res)
    d.train_returns.extend(res["episodes"])
    d.train_lengths.extend(res["lengths"])
    d.collector_versions[i] = int(res.get("version", -1))
    d.limiter_blocked += int(bool(res.get("limiter_blocked")))
    d.outage_since = None  # a call that went through: replay is reachable


def _learner_answer(d: "Driver", i: int, res: dict) -> None:
    c = d.c
    c.updates, c.version, c.nan_skips = int(res["updates"]), int(res["version"]), int(res["nan_skips"])
    c.sampled_sequences = int(res["sampled_sequences"])
    c.busy["learner"] = float(res["busy_seconds"])  # the learner reports its running total
    d.learner_sample_wait = float(res.get("sample_wait_seconds", 0.0))
    if res["losses"]:
        d.losses = res["losses"]
    if res["status"] == "nan_stop":
        d.stop_reason = ("nan_stop", res["message"])
    elif res["status"] == "error":
        d.stop_reason = ("error", res["message"])
    d.outage_since = None
    d.maybe_checkpoint()


def _reanalyzer_answer(d: "Driver", i: int, res: dict) -> None:
    d.c.reanalyzed += int(res["reanalyzed"])
    answer_busy(d, "reanalyzer", res)


def _evaluator_answer(d: "Driver", i: int, res: dict) -> None:
    answer_busy(d, "evaluator", res)
    if res["returns"]:
        d.record_eval(res)


# -- the built-in roles -----------------------------------------------------------------------
def _late(module: str, name: str) -> Callable[[], type]:
    """The class `module.name`, imported when a role is built (the actors import torch)."""
    def load() -> type:
        import importlib

        return getattr(importlib.import_module(module), name)
    return load


_collector_cls = _late("wmdist.runtime.roles.collector", "Collector")
_learner_cls = _late("wmdist.runtime.roles.learner", "LearnerRole")
_reanalyzer_cls = _late("wmdist.runtime.roles.reanalyzer", "ReanalyzerRole")
_evaluator_cls = _late("wmdist.runtime.roles.evaluator", "EvaluatorRole")
_shard_cls = _late("wmdist.runtime.roles.replay_actor", "ShardActor")
_limiter_cls = _late("wmdist.runtime.roles.replay_actor", "LimiterActor")


def _sized(section: Any) -> RoleResources:
    """A section with `cpus`, `gpus` and `resources` fields."""
    return RoleResources(section.cpus, section.gpus, dict(section.resources))


LEARNER_SLICE_SECONDS = 1.0  # one learner call trains this long, so the driver hears from it often
# The local runner runs one role at a time: shorter slices let the collectors take their turns
# often enough that the limiter, not the slice length, sets the train ratio.
LOCAL_LEARNER_SLICE_SECONDS = 0.1

BUILTIN: tuple[Role, ...] = (
    # Replay is created by `runtime.replay_client.create_replay` (shards must exist before any
    # role that writes to them); its entries give the resources and restart policy it uses.
    Role("replay", _shard_cls, lambda cfg: cfg.replay, lambda cfg: cfg.replay.shards,
         lambda sec: RoleResources(sec.shard_cpus, custom=dict(sec.resources)), schedule=SERVICE,
         options={"max_concurrency": 8, "max_task_retries": 3}, owner="replay", metrics=()),
    # the limiter's state is counts: Ray restarts it (its calls retried on the new process), and
    # the driver gives it the shards' size again (`ReplayClient.resync_limiter`)
    Role("limiter", _limiter_cls, lambda cfg: cfg.replay, lambda cfg: 1,
         lambda sec: RoleResources(0.0, custom=dict(sec.resources)), schedule=SERVICE,
         options={"max_concurrency": 64, "max_task_retries": -1}, owner="replay", metrics=()),
    Role("learner", _learner_cls, lambda cfg: cfg.learner, lambda cfg: 1, _sized,
         args=lambda ctx, i, res: (ctx.cfg, ctx.spec, ctx.replay, ctx.broker, res.threads, dict(ctx.actors)),
         max_restarts=lambda cfg: 0, schedule=LOOP, fatal=True, options={"max_concurrency": 1}, ready_first=True,
         call=lambda a, d: a.train_for.remote(d.learner_slice, d.cfg.run.max_updates),
         handle=_learner_answer, metrics=("wmdist_busy_seconds_total", "wmdist_learner_updates_total")),
    Role("collector", _collector_cls, lambda cfg: cfg.actors, lambda cfg: cfg.actors.num, _sized,
         args=lambda ctx, i, res: (ctx.cfg, ctx.spec, i, ctx.replay, ctx.broker, res.threads),
         max_restarts=lambda cfg: cfg.actors.max_restarts, schedule=LOOP,
         call=lambda a, d: a.run_segment.remote(d.c.env_steps, d.c.updates), handle=_collector_answer,
         metrics=("wmdist_busy_seconds_total", "wmdist_actor_restarts_total", "wmdist_env_steps_total")),
    Role("reanalyzer", _reanalyzer_cls, lambda cfg: cfg.reanalyze, lambda cfg: cfg.reanalyze.num, _sized,
         args=lambda ctx, i, res: (ctx.cfg, ctx.spec, i, ctx.replay, ctx.broker, res.threads),
         schedule=PACED, call=lambda a, d: a.run_job.remote(), handle=_reanalyzer_answer, drain=False,
         metrics=("wmdist_busy_seconds_total", "wmdist_actor_restarts_total", "wmdist_reanalyzed_sequences_total")),
    Role("evaluator", _evaluator_cls, lambda cfg: cfg.eval, lambda cfg: int(cfg.eval.enabled), _sized,
         args=lambda ctx, i, res: (ctx.cfg, ctx.spec, ctx.broker, res.threads),
         schedule=PERIODIC, call=lambda a, d: a.evaluate.remote(), handle=_evaluator_answer,
         metrics=("wmdist_busy_seconds_total", "wmdist_actor_restarts_total", "wmdist_episode_return")),
)

BUILTIN_NAMES = tuple(r.name for r in BUILTIN)


def table(cfg: RunConfig, algo_roles: tuple[Role, ...] = ()) -> tuple[Role, ...]:
    """The run's roles: the built-in ones, then the algorithm's own (names must be new)."""
    names = set(BUILTIN_NAMES)
    for r in algo_roles:
        if r.name in names:
            raise ValueError(f"algorithm role {r.name!r} clashes with a role already in the table")
        names.add(r.name)
    return (*BUILTIN, *algo_roles)


def algorithm_roles(cfg: RunConfig) -> tuple[Role, ...]:
    """The roles the configured algorithm adds (`Algorithm.extra_roles`)."""
    from wmdist.algos.registry import resolve

    return tuple(resolve(cfg.algo_name).extra_roles(cfg))


def run_roles(cfg: RunConfig) -> tuple[Role, ...]:
    return table(cfg, algorithm_roles(cfg))


def by_name(roles: tuple[Role, ...]) -> dict[str, Role]:
    return {r.name: r for r in roles}
