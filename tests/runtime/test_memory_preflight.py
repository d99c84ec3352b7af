"""A batch or a replay store too big for the machine is one line and exit 2 before anything starts.

Session 32 found `--set learner.batch_size=1e9` accepted: the run started, and Ray's memory
monitor then killed the learner of another run on the same node.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from wmdist.algos.base import FieldSpec
from tests.runtime.one_line import one_line_exit_2
from wmdist.config.errors import ConfigError
from wmdist.config.loader import load_config
from wmdist.runtime.preflight_memory import check_memory, node_memory_bytes, step_bytes

ROOT = Path(__file__).resolve().parents[2]
MUZERO = str(ROOT / "configs" / "muzero_cartpole.yaml")
GiB = 1 << 30




def _one_line_exit_2(capsys, argv: list[str]) -> str:
    return one_line_exit_2(capsys, argv)[0]


@pytest.mark.parametrize("sets, names", [
    (["learner.batch_size=1000000000"], "learner.batch_size"),
    (["replay.capacity_steps=100000000000"], "replay.capacity_steps"),
    (["reanalyze.num=1", "reanalyze.batch_size=1000000000"], "reanalyze.batch_size"),
])
def test_too_big_for_the_machine_is_one_line_before_anything_starts(tmp_path, capsys, nothing_starts, sets, names):
    line = _one_line_exit_2(capsys, ["train", MUZERO, "--set", f"run.dir={tmp_path}", *sets])
    assert names in line and "memory" in line
    assert not any(tmp_path.iterdir()), "a run directory was created"


def _fields() -> dict:
    return {"obs": FieldSpec((64, 64, 3), "uint8"), "action": FieldSpec((), "int64"), "reward": FieldSpec((), "float32")}


def test_step_bytes_counts_every_field_and_the_flags():
    assert step_bytes(_fields()) == 1 + 64 * 64 * 3 + 8 + 4


def test_limits_by_hand_at_a_given_memory():
    cfg = load_config(MUZERO, ["replay.seq_len=10", "replay.overlap=2", "replay.capacity_steps=1000", "learner.batch_size=100"])
    per = step_bytes(_fields())                       # 12,301 bytes
    batch = 100 * 10 * per                            # 12.3 MB
    check_memory(cfg, _fields(), memory=4 * batch)    # exactly a quarter: passes
    with pytest.raises(ConfigError, match="learner.batch_size"):
        check_memory(cfg, _fields(), memory=4 * batch - 1)
    big = load_config(MUZERO, ["replay.seq_len=10", "replay.overlap=2", "replay.capacity_steps=10000000", "learner.batch_size=1"])
    need = 10_000_000 * per
    check_memory(big, _fields(), memory=need)
    with pytest.raises(ConfigError, match="replay.capacity_steps"):
        check_memory(big, _fields(), memory=need - 1)
    # capacity_bytes caps what the store will hold: the same capacity then fits
    capped = load_config(MUZERO, ["replay.seq_len=10", "replay.overlap=2", "replay.capacity_steps=10000000", "learner.batch_size=1",
                                  f"replay.capacity_bytes={GiB}"])
    check_memory(capped, _fields(), memory=2 * GiB)
    # a store on a cluster's other node is not judged by this machine's memory
    joined = load_config(MUZERO, ["replay.seq_len=10", "replay.overlap=2", "replay.capacity_steps=10000000", "learner.batch_size=1",
                                  "ray.address=10.0.0.1:6379"])
    check_memory(joined, _fields(), memory=need - 1)


def test_this_machine_reports_its_memory():
    mem = node_memory_bytes()
    assert mem is not None and mem > 256 * 1024 * 1024
