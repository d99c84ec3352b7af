"""Run in its own process: a head and two worker nodes on this machine
(`ray.cluster_utils.Cluster`); collectors on the workers by a custom resource, replay and the
learner on the head. Mid-run one worker node is removed (its processes die with it). Prints
one JSON line: where the collectors ran before and after, restarts, and the replay's
accounting (every acknowledged sequence is either stored or counted as evicted)."""
from __future__ import annotations

import json
import sys
import tempfile
import threading
import time
from pathlib import Path

import ray
from ray.cluster_utils import Cluster

from wmdist.config.loader import load_config
from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.roles.setup import build_algorithm
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

FAKE = str(Path(__file__).parents[1] / "runtime" / "fake.yaml")


class _Counting(Driver):
    """Sums the sequences collectors report as inserted (acknowledged by replay)."""

    acked = 0

    def _handle(self, kind, i, res):
        if kind == "collector":
            self.acked += int(res.get("inserted", 0))
        super()._handle(kind, i, res)


def main() -> None:
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                            "resources": {"head": 8}})
    workers = [cluster.add_node(num_cpus=1, resources={"collector_node": 4}) for _ in range(2)]
    t0 = time.monotonic()
    ray.init(address=cluster.address, log_to_driver=False)
    tmp = Path(tempfile.mkdtemp())
    cfg = load_config(FAKE, [f"run.dir={tmp}", "run.max_minutes=3", "actors.num=2",
                             "actors.resources={collector_node: 1}", "replay.resources={head: 1}",
                             "learner.resources={head: 1}", "replay.shards=1"])
    spec = env_spec_or_error(cfg)
    topo = build(cfg, spec, tmp, build_algorithm(cfg, spec, 0).step_fields())
    try:
        before = ray.get([c.node_id.remote() for c in topo.collectors])
        doomed = next(w for w in workers if w.node_id == before[0])  # the node of collector 0 goes away
        spare = next(w for w in workers if w is not doomed)
        print(f"actors up {time.monotonic() - t0:.1f}s", file=sys.stderr, flush=True)
        driver = _Counting(topo, Counters())

        def remove_worker() -> None:
            while driver.c.env_steps < 400 and driver.elapsed() < 120:
                time.sleep(0.2)
            print(f"removing {time.monotonic() - t0:.1f}s", file=sys.stderr, flush=True)
            cluster.remove_node(doomed)
            print(f"removed {time.monotonic() - t0:.1f}s", file=sys.stderr, flush=True)
            # then run until both collectors answered from the spare node
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                time.sleep(1.0)
                try:
                    nodes = ray.get([c.node_id.remote() for c in topo.collectors], timeout=10)
                except Exception:  # noqa: BLE001 - still coming back
                    continue
                if set(nodes) == {spare.node_id} and driver.c.restarts["collector"] >= 1:
                    break
            print(f"back {time.monotonic() - t0:.1f}s", file=sys.stderr, flush=True)
            time.sleep(3.0)  # a few more segments on the spare node
            driver.request_stop("node-loss test done")

        threading.Thread(target=remove_worker, daemon=True).start()
        result = driver.run()
        after = ray.get([c.node_id.remote() for c in topo.collectors])
        stats = topo.replay.stats()
        print(json.dumps({
            "status": result.status, "message": result.message, "before": before, "after": after,
            "doomed": doomed.node_id, "spare": spare.node_id, "workers": [w.node_id for w in workers],
            "restarts": result.counters.restarts,
            "env_steps": result.counters.env_steps, "updates": result.counters.updates,
            "acked": driver.acked, "stored": stats.get("size_sequences", 0),
            "evicted": stats.get("drops_evicted", 0), "inserts": stats.get("inserts", 0),
        }))
    finally:
        topo.shutdown()
        ray.shutdown()
        cluster.shutdown()


if __name__ == "__main__":
    sys.exit(main())
