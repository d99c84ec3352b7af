"""Run in its own process (a second Ray instance can't share the test session's driver):
a head node and one worker node on this machine via `ray.cluster_utils.Cluster`; the config
places collectors on the worker by a custom resource; prints one JSON line of results."""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import ray
from ray.cluster_utils import Cluster

from wmdist.config.loader import load_config
from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.roles.setup import build_algorithm
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

FAKE = str(Path(__file__).parents[1] / "runtime" / "fake.yaml")


def main() -> None:
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    worker = cluster.add_node(num_cpus=1, resources={"collector_node": 4})
    ray.init(address=cluster.address, log_to_driver=False)
    tmp = Path(tempfile.mkdtemp())
    cfg = load_config(FAKE, [f"run.dir={tmp}", "run.max_updates=30", "run.max_minutes=1.5",
                             "actors.num=2", "actors.resources={collector_node: 1}", "replay.shards=1"])
    spec = env_spec_or_error(cfg)
    topo = build(cfg, spec, tmp, build_algorithm(cfg, spec, 0).step_fields())
    try:
        nodes = ray.get([c.node_id.remote() for c in topo.collectors])
        result = Driver(topo, Counters()).run()
        print(json.dumps({"collector_nodes": nodes, "worker_node": worker.node_id, "driver_node": ray.get_runtime_context().get_node_id(),
                          "updates": result.counters.updates, "env_steps": result.counters.env_steps,
                          "status": result.status}))
    finally:
        topo.shutdown()
        ray.shutdown()
        cluster.shutdown()


if __name__ == "__main__":
    sys.exit(main())
