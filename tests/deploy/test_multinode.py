"""Collectors land on the worker node named by resource labels in the config, and training
progresses across two Ray nodes (head + worker on this machine)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[2]


def test_collectors_placed_on_worker_node_by_config_resources():
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "tests.deploy.multinode_run"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=280)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["status"] == "done"
    assert set(out["collector_nodes"]) == {out["worker_node"]}  # both collectors on the tagged worker
    assert out["updates"] >= 30 and out["env_steps"] > 0


def test_a_lost_worker_node_costs_no_acknowledged_sequence():
    """A worker node removed mid-run: its collector comes back on the remaining node, the run
    goes on, and replay (on the head) holds or has counted every sequence it acknowledged."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-m", "tests.deploy.node_loss_run"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=290)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["status"] == "done", out
    assert out["doomed"] in out["before"], out  # a collector was on the node that went away
    assert set(out["after"]) == {out["spare"]}, out
    assert out["restarts"]["collector"] >= 1, out
    assert 0 < out["acked"] <= out["inserts"] == out["stored"] + out["evicted"], out
