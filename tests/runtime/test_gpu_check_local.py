"""The CUDA check's path (`wmdist.bench.gpu_check`) runs where Ray is not installed.

The GPU machines this project borrows have torch but no Ray, so the local runner it uses
must never import Ray: here Ray's import is made to fail in a fresh interpreter and the
check's CPU self-test (`--device cpu`) must still collect, update and pass.
"""
from __future__ import annotations

import json
import subprocess
import sys

CODE = """
import sys
sys.modules["ray"] = None  # `import ray` now raises ImportError
from wmdist.bench.gpu_check import main
sys.exit(main(["--device", "cpu", "--seconds", "0.2", "muzero_cartpole.yaml"]))
"""


def test_gpu_check_runs_without_ray() -> None:
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, timeout=240,
                         env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, out.stderr[-2000:]
    line = json.loads(out.stdout.splitlines()[0])
    assert line["preset"] == "muzero_cartpole.yaml" and line["ok"] is True
    assert line["updates_per_s"] > 0 and line["env_steps_per_s"] > 0
