"""Per-role Ray resources, torch threads, and the check that a config fits the cluster."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from wmdist.config.errors import ConfigError
from wmdist.config.schema import RunConfig

# The weight broker only forwards object refs: it needs no CPU of its own.
BROKER_CPUS = 0.0


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


def roles(cfg: RunConfig) -> dict[str, tuple[RoleResources, int]]:
    """role -> (resources of one actor, number of actors)."""
    out = {
        "collector": (RoleResources(cfg.actors.cpus, cfg.actors.gpus, cfg.actors.resources), cfg.actors.num),
        "learner": (RoleResources(cfg.learner.cpus, cfg.learner.gpus, cfg.learner.resources), 1),
        "replay": (RoleResources(cfg.replay.shard_cpus, custom=cfg.replay.resources), cfg.replay.shards),
        "limiter": (RoleResources(0.0, custom=cfg.replay.resources), 1),
        "reanalyzer": (RoleResources(cfg.reanalyze.cpus, cfg.reanalyze.gpus, cfg.reanalyze.resources), cfg.reanalyze.num),
    }
    if cfg.eval.every_seconds > 0:
        out["evaluator"] = (RoleResources(cfg.eval.cpus), 1)
    return out


def check_fits(cfg: RunConfig, cluster: dict[str, float]) -> None:
    """One clear error, before any actor starts, when the roles ask for more than exists."""
    need: dict[str, float] = {}
    for res, n in roles(cfg).values():
        need["CPU"] = need.get("CPU", 0.0) + res.cpus * n
        need["GPU"] = need.get("GPU", 0.0) + res.gpus * n
        for k, v in res.custom.items():
            need[k] = need.get(k, 0.0) + float(v) * n
    for key, amount in need.items():
        have = float(cluster.get(key, 0.0))
        if amount > have + 1e-6:
            detail = ", ".join(f"{r} {res.cpus if key == 'CPU' else res.gpus if key == 'GPU' else res.custom.get(key, 0)} x {n}"
                               for r, (res, n) in roles(cfg).items())
            raise ConfigError(f"the config needs {amount:g} {key} but the cluster has {have:g} ({detail}); "
                              f"lower actors.num or the per-role cpus")
