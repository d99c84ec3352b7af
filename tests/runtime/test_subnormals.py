"""Every role process flushes subnormal floats to zero (`set_threads`), and the subnormals bench
times what that buys against the unflushed path in the same process."""
import json
import subprocess
import sys

PROBE = r"""
import torch
x = torch.tensor([1e-39, -2e-39, 1e-30], dtype=torch.float32)  # two subnormals, one normal
before = (x * 1.0).tolist()
from wmdist.runtime.roles.setup import set_threads
set_threads(1)
print(before, (x * 1.0).tolist())
"""


def test_a_role_process_flushes_subnormals_to_zero():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True).stdout
    before, after = _two(out)
    assert before[0] != 0 and before[1] != 0  # the process starts unflushed: the probe can fail
    assert after[:2] == [0.0, 0.0] and after[2] > 0  # flushed; normal floats untouched


def _two(out: str) -> tuple[list[float], list[float]]:
    first, second = out.strip()[1:-1].split("] [")
    return [float(v) for v in first.split(",")], [float(v) for v in second.split(",")]


def test_the_bench_times_planted_subnormals_with_flushing_off_and_on():
    from wmdist.bench.subnormals import run

    cases = {c["case"]: c for c in run(quick=True, planted=0.001)}
    off, on = cases["flush=off"], cases["flush=on"]
    assert 0.0005 < off["subnormal_share"] < 0.002  # the planted share, as reported
    for case in (off, on):  # both settings timed on both nets (the figures: BENCHMARKS.md, not a timed test)
        assert case["fresh_ms"] > 0 and case["subnormal_ms"] > 0
        assert abs(case["slowdown"] - case["subnormal_ms"] / case["fresh_ms"]) < 0.01
    assert cases["flush gain"]["ratio"] > 0
    json.dumps(cases)  # one JSON object per case
