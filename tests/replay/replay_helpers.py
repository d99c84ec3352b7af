"""Shared helpers of the replay tests: small fields and batches with recognisable contents."""
from __future__ import annotations

import time

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch

FIELDS = {
    "obs": FieldSpec((3,), "float32"),
    "action": FieldSpec((), "int64"),
    "reward": FieldSpec((), "float32"),
    "first": FieldSpec((), "bool"),
    "last": FieldSpec((), "bool"),
    "terminal": FieldSpec((), "bool"),
    "root_value": FieldSpec((), "float32"),
}
T = 8


def make_batch(n: int, seq_len: int = T, start: int = 0, steps: np.ndarray | None = None) -> SequenceBatch:
    """n windows whose obs encode (sequence id, step) so tests can tell them apart."""
    ids = np.arange(start, start + n)
    steps = np.full(n, seq_len) if steps is None else np.asarray(steps)
    mask = np.arange(seq_len)[None, :] < steps[:, None]  # [N, T]
    obs = np.zeros((n, seq_len, 3), np.float32)
    obs[..., 0] = ids[:, None]
    obs[..., 1] = np.arange(seq_len)[None, :]
    obs *= mask[..., None]
    data = {
        "obs": obs,
        "action": (ids[:, None] * 10 + np.arange(seq_len)).astype(np.int64) * mask,
        "reward": np.ones((n, seq_len), np.float32) * mask,
        "first": np.zeros((n, seq_len), bool),
        "last": mask & (np.arange(seq_len)[None, :] == steps[:, None] - 1),
        "terminal": np.zeros((n, seq_len), bool),
        "root_value": np.zeros((n, seq_len), np.float32),
    }
    return SequenceBatch(data, mask, ids.astype(np.int64), ids.astype(np.int64))


def sample_ids(sample) -> np.ndarray:
    """[B] the sequence id each sampled row encodes (see `make_batch`)."""
    return sample.data["obs"][:, 0, 0].astype(int)


def wait_shard_restarted(client, pid: int, shard: int = 0) -> None:
    """Until Ray has restarted `client`'s shard (a new process id), at most 60 s; its __init__
    rebuilds the index (from redis, or by re-attaching the shared-memory segment)."""
    import ray

    deadline = time.monotonic() + 60
    while True:
        try:
            if ray.get(client.shards[shard].pid.remote(), timeout=10) != pid:
                return
        except Exception:  # noqa: BLE001 - the actor is still coming back
            pass
        assert time.monotonic() < deadline, "shard did not come back"
        time.sleep(0.2)
