"""Collectors land on the worker nodes named by resource labels in the config, training
progresses across three Ray nodes (head + two workers on this machine), and losing a worker
node costs no acknowledged sequence. One cluster serves both checks: each start costs ~20 s."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[2]


def test_collectors_placed_by_resources_and_a_lost_worker_node_costs_no_acknowledged_sequence():
    """Collectors start on the tagged worker nodes; one node removed mid-run: its collector comes back on the remaining node, the run
    goes on, and replay (on the head) holds or has counted every sequence it acknowledged."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "tests.deploy.node_loss_run"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=290)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["status"] == "done", out
    assert set(out["before"]) <= set(out["workers"]), out  # placed by `actors.resources`, never on the head
    assert out["updates"] >= 30 and out["env_steps"] > 0, out
    assert out["doomed"] in out["before"], out  # a collector was on the node that went away
    assert set(out["after"]) == {out["spare"]}, out
    assert out["restarts"]["collector"] >= 1, out
    assert 0 < out["acked"] <= out["inserts"] == out["stored"] + out["evicted"], out
