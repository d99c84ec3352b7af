"""The check that a config's roles fit the cluster, summed over the table of roles."""
from __future__ import annotations

from wmdist.config.errors import ConfigError
from wmdist.config.schema import RunConfig
from wmdist.runtime.table import Role, RoleResources, run_roles

# The weight broker only forwards object refs: it needs no CPU of its own.
BROKER_CPUS = 0.0

__all__ = ["BROKER_CPUS", "RoleResources", "check_fits", "roles"]


def roles(cfg: RunConfig, table: tuple[Role, ...] | None = None) -> dict[str, tuple[RoleResources, int]]:
    """role -> (resources of one actor, number of actors), for every role with actors."""
    table = run_roles(cfg) if table is None else table
    return {r.name: (r.resources_of(cfg), r.count(cfg)) for r in table if r.count(cfg) > 0}


_FIELD = {"CPU": "cpus", "GPU": "gpus"}  # the per-role field that asks for each resource


def check_fits(cfg: RunConfig, cluster: dict[str, float], table: tuple[Role, ...] | None = None) -> None:
    """One clear error, before any actor starts, when the roles ask for more than exists."""
    per_role = roles(cfg, table)
    need: dict[str, float] = {}
    for res, n in per_role.values():
        need["CPU"] = need.get("CPU", 0.0) + res.cpus * n
        need["GPU"] = need.get("GPU", 0.0) + res.gpus * n
        for k, v in res.custom.items():
            need[k] = need.get(k, 0.0) + float(v) * n
    for key, amount in need.items():
        have = float(cluster.get(key, 0.0))
        if amount > have + 1e-6:
            detail = ", ".join(f"{r} {res.cpus if key == 'CPU' else res.gpus if key == 'GPU' else res.custom.get(key, 0)} x {n}"
                               for r, (res, n) in per_role.items())
            raise ConfigError(f"the config needs {amount:g} {key} but the cluster has {have:g} ({detail}); "
                              f"lower actors.num or the per-role {_FIELD.get(key, 'resources')}")
