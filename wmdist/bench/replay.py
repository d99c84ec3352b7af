"""Replay throughput against raw limits measured in the same run.

Cases: vector observations (T=64, 20 float32) and pixels (T=64, 64x64x3 uint8), 1 and 2
shards, memory and redis backends (a private redis-server, appendfsync everysec). Each case
reports inserts and samples per second and MB/s through the real service (Ray actors,
limiter off), next to the raw limit for the same bytes: a numpy copy (memory backend) or
redis-py pipelined SET / GET of one blob per sequence (redis backend), and the memory per
stored step against the raw bytes per step.
"""
from __future__ import annotations

import tempfile
import time
from typing import Iterator

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.config import ReplayConfig

T = 64
OBS = {"vector": FieldSpec((20,), "float32"), "pixels": FieldSpec((64, 64, 3), "uint8")}


def _fields(kind: str) -> dict[str, FieldSpec]:
    return {"obs": OBS[kind], "action": FieldSpec((), "int64"), "reward": FieldSpec((), "float32"),
            "first": FieldSpec((), "bool"), "last": FieldSpec((), "bool"), "terminal": FieldSpec((), "bool")}


def _batch(fields: dict[str, FieldSpec], n: int, start: int, rng: np.random.Generator) -> SequenceBatch:
    data = {k: (rng.random((n, T, *s.shape)) * 200).astype(s.dtype) for k, s in fields.items()}
    ids = np.arange(start, start + n, dtype=np.int64)
    return SequenceBatch(data, np.ones((n, T), bool), np.zeros(n, np.int64), ids)


def _timed(fn, reps: int) -> float:
    t0 = time.perf_counter()
    for i in range(reps):
        fn(i)
    return time.perf_counter() - t0


def _raw_numpy(batch: SequenceBatch, reps: int) -> tuple[float, float]:
    """Seconds per batch for copying the batch's arrays into preallocated rings and back out."""
    ring = {k: np.empty((len(batch) * 2, *v.shape[1:]), v.dtype) for k, v in batch.data.items()}
    idx = np.arange(len(batch))

    def put(i):
        for k, v in batch.data.items():
            ring[k][idx] = v

    def get(i):
        for v in ring.values():
            v[idx]

    return _timed(put, reps) / reps, _timed(get, reps) / reps


def _raw_redis(client, batch: SequenceBatch, reps: int) -> tuple[float, float]:
    """Seconds per batch for pipelined SET / GET of one blob per sequence (same bytes)."""
    n = len(batch)
    blobs = [b"".join(v[i].tobytes() for v in (*batch.data.values(), batch.mask)) for i in range(n)]
    keys = [f"wmdist:bench:raw:{i}" for i in range(n)]

    def put(_):
        p = client.pipeline(transaction=False)
        for k, b in zip(keys, blobs):
            p.set(k, b)
        p.execute()

    def get(_):
        p = client.pipeline(transaction=False)
        for k in keys:
            p.get(k)
        p.execute()

    out = _timed(put, reps) / reps, _timed(get, reps) / reps
    client.delete(*keys)
    return out


def _case(kind: str, shards: int, backend: str, quick: bool, run_dir: str) -> dict:
    from wmdist.runtime.replay_client import create_replay

    fields = _fields(kind)
    ins_batch = 32 if kind == "vector" else 8  # sequences per insert call
    sample_b = 32 if kind == "vector" else 16
    reps = (5 if quick else 20) if kind == "vector" else (4 if quick else 12)
    capacity_seq = ins_batch * reps * 2
    cfg = ReplayConfig(backend=backend, shards=shards, capacity_steps=capacity_seq * T, seq_len=T,
                       min_size=0, samples_per_insert=0, shard_cpus=0.1)
    rng = np.random.default_rng(0)
    batches = [_batch(fields, ins_batch, i * ins_batch, rng) for i in range(reps)]
    seq_bytes = batches[0].nbytes / ins_batch
    client = create_replay(cfg, fields, run_dir, f"bench-{kind}-{shards}-{backend}")
    try:
        rc = client._server.client() if backend == "redis" else None
        used0 = rc.info("memory")["used_memory"] if rc else 0
        client.insert(batches[0], source_id=0)  # warm up actors and connections
        t_ins = _timed(lambda i: client.insert(batches[i], source_id=i), reps)
        client.sample(sample_b)
        t_smp = _timed(lambda i: client.sample(sample_b), reps)
        st = client.stats()
        raw_step = seq_bytes / T  # fields + 1-byte mask
        if backend == "memory":  # preallocated rings + index, per step of capacity
            mem = st["bytes"] / (st["capacity_sequences"] * T)
        else:  # redis-server's own accounting, per stored step (shard index excluded)
            mem = (rc.info("memory")["used_memory"] - used0) / (st["size_sequences"] * T)
        sample_batch = batches[0].select(np.arange(min(sample_b, ins_batch)))
        if backend == "memory":
            raw_put, _ = _raw_numpy(batches[0], reps)
            _, raw_get = _raw_numpy(sample_batch, reps)
        else:
            raw_put, _ = _raw_redis(rc, batches[0], reps)
            _, raw_get = _raw_redis(rc, sample_batch, reps)
        raw_get *= sample_b / len(sample_batch)
    finally:
        client.close()
    ins_sps = reps * ins_batch / t_ins
    smp_sps = reps * sample_b / t_smp
    raw_ins_sps, raw_smp_sps = ins_batch / raw_put, sample_b / raw_get
    mb = seq_bytes / 1e6
    return {
        "bench": "replay", "obs": kind, "shards": shards, "backend": backend, "seq_len": T,
        "insert_batch": ins_batch, "sample_batch": sample_b, "seq_bytes": int(seq_bytes),
        "insert_seq_per_s": round(ins_sps, 1), "insert_mb_per_s": round(ins_sps * mb, 1),
        "sample_seq_per_s": round(smp_sps, 1), "sample_mb_per_s": round(smp_sps * mb, 1),
        "raw": "numpy copy" if backend == "memory" else "redis-py pipelined SET/GET",
        "raw_insert_mb_per_s": round(raw_ins_sps * mb, 1), "raw_sample_mb_per_s": round(raw_smp_sps * mb, 1),
        "insert_vs_raw": round(ins_sps / raw_ins_sps, 3), "sample_vs_raw": round(smp_sps / raw_smp_sps, 3),
        "bytes_per_stored_step": round(mem, 1), "raw_bytes_per_step": round(raw_step, 1),
        "memory_vs_raw": round(mem / raw_step, 3),
    }


def run(quick: bool = False) -> Iterator[dict]:
    import ray

    started = not ray.is_initialized()
    if started:
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        with tempfile.TemporaryDirectory(prefix="wmdist-bench-replay-") as run_dir:
            kinds = ["vector"] if quick else ["vector", "pixels"]
            for kind in kinds:
                for shards in [1] if quick else [1, 2]:
                    for backend in ("memory", "redis"):
                        yield _case(kind, shards, backend, quick, run_dir)
    finally:
        if started:
            ray.shutdown()
