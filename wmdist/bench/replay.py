"""Replay throughput against raw limits measured in the same run.

Cases: vector observations (T=64, 20 float32) and pixels (T=64, 64x64x3 uint8), 1 and 2
shards, memory and redis backends (a private redis-server, appendfsync everysec). Each case
reports inserts and samples per second and MB/s through the real service (Ray actors,
limiter off), next to the raw limit for the same bytes: a numpy copy (memory backend) or
redis-py pipelined SET / GET of one blob per sequence (redis backend; a raw sample also cuts
its blobs into the batch arrays, and the GET alone is reported too); figures are medians
over rounds that alternate service and raw calls, so machine load hits both alike (the
cyclic GC paused while timing, since its pauses land on either side at random). Also the
memory per stored step against the raw bytes per step.
"""
from __future__ import annotations

import gc
import os
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


def _time(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


class _RawNumpy:
    """The raw limit of the memory backend: copying the same arrays into / out of ring arrays."""

    def __init__(self, batch: SequenceBatch, slots: int) -> None:
        self.ring = {k: np.empty((slots, *v.shape[1:]), v.dtype) for k, v in batch.data.items()}
        self.ring["mask"] = np.empty((slots, T), bool)

    def put(self, batch: SequenceBatch, i: int) -> None:
        rows = (np.arange(len(batch)) + i * len(batch)) % len(self.ring["mask"])
        for k, v in batch.data.items():
            self.ring[k][rows] = v
        self.ring["mask"][rows] = batch.mask

    def get(self, n: int, i: int) -> None:
        rows = (np.arange(n) + i * n) % len(self.ring["mask"])
        for v in self.ring.values():
            v[rows]


class _RawRedis:
    """The raw limit of the redis backend: pipelined SET / GET of one blob per sequence (the
    same array bytes, fresh keys per round like the service's inserts). A sample is a batch of
    arrays, so `get` also cuts the blobs into `[B, T, ...]` arrays the cheapest way (the work
    the service's decode does, minus its checks); `get_bytes` is the GET alone."""

    def __init__(self, client, batch: SequenceBatch) -> None:
        self.r, self.keys = client, []
        cols = [*batch.data.values(), batch.mask]
        self.dtypes = [c.dtype for c in cols]
        self.shapes = [c.shape[1:] for c in cols]
        self.nbytes = [c[0].nbytes for c in cols]
        self.offsets = np.cumsum([0, *self.nbytes])[:-1].tolist()

    def put(self, batch: SequenceBatch, i: int) -> None:
        p = self.r.pipeline(transaction=False)
        cols = [*batch.data.values(), batch.mask]
        for row in range(len(batch)):
            key = f"wmdist:bench:raw:{i}:{row}"
            self.keys.append(key)
            p.set(key, b"".join([c[row] for c in cols]))  # one copy of each row's arrays
        p.execute()

    def get_bytes(self, n: int, i: int) -> list[bytes]:
        p = self.r.pipeline(transaction=False)
        for j in range(n):
            p.get(self.keys[(i * n + j) % len(self.keys)])
        return p.execute()

    def get(self, n: int, i: int) -> list[np.ndarray]:
        blobs = self.get_bytes(n, i)
        out = [np.empty((n, *s), dt) for s, dt in zip(self.shapes, self.dtypes)]
        flat = [a.reshape(n, -1).view(np.uint8) for a in out]
        size = sum(self.nbytes)
        if size <= 1 << 16:  # small: one copy per blob, then one per field for the batch
            buf = np.empty((n, size), np.uint8)
            for j, b in enumerate(blobs):
                buf[j] = np.frombuffer(b, np.uint8)
            for f, o, k in zip(flat, self.offsets, self.nbytes):
                f[:] = buf[:, o:o + k]
        else:  # large: each field of each blob copied once
            for j, b in enumerate(blobs):
                for f, o, k in zip(flat, self.offsets, self.nbytes):
                    f[j] = np.frombuffer(b, np.uint8, k, o)
        return out

    def close(self) -> None:
        for j in range(0, len(self.keys), 1000):
            self.r.delete(*self.keys[j:j + 1000])


def _case(kind: str, shards: int, backend: str, quick: bool, run_dir: str) -> dict:
    from wmdist.runtime.replay_client import create_replay

    fields = _fields(kind)
    ins_batch = 32 if kind == "vector" else 8  # sequences per insert call
    sample_b = 32 if kind == "vector" else 16
    reps = (6 if quick else 64) if kind == "vector" else (4 if quick else 24)  # medians of many rounds
    capacity_seq = ins_batch * (reps + 1) * 2
    cfg = ReplayConfig(backend=backend, shards=shards, capacity_steps=capacity_seq * T, seq_len=T,
                       min_size=0, samples_per_insert=0, shard_cpus=0.1)
    rng = np.random.default_rng(0)
    batches = [_batch(fields, ins_batch, i * ins_batch, rng) for i in range(reps + 1)]
    seq_bytes = batches[0].nbytes / ins_batch
    client = create_replay(cfg, fields, run_dir, f"bench-{kind}-{shards}-{backend}")
    raw = None
    try:
        rc = client._server.client() if backend == "redis" else None
        used0 = rc.info("memory")["used_memory"] if rc else 0
        client.insert(batches[-1], source_id=0)  # warm up actors and connections
        client.sample(sample_b)
        raw = _RawNumpy(batches[0], capacity_seq) if backend == "memory" else _RawRedis(rc, batches[0])
        # rounds alternate service and raw calls on the same bytes, so load noise hits both; the
        # cyclic GC is paused while timing (its pauses land on either side at random)
        gc.collect()
        gc.disable()
        ins, raw_ins = [], []
        for i in range(reps):
            ins.append(_time(lambda: client.insert(batches[i], source_id=i)))
            raw_ins.append(_time(lambda: raw.put(batches[i], i)))
        st = client.stats()
        mem_raw = rc.info("memory")["used_memory"] - used0 if rc else 0
        smp, raw_smp, raw_bytes = [], [], []
        for i in range(reps):
            smp.append(_time(lambda: client.sample(sample_b)))
            raw_smp.append(_time(lambda: raw.get(sample_b, i)))
            if backend == "redis":
                raw_bytes.append(_time(lambda: raw.get_bytes(sample_b, i)))
    finally:
        gc.enable()
        if isinstance(raw, _RawRedis):
            raw.close()
        client.close()
    raw_step = seq_bytes / T  # fields + 1-byte mask
    if backend == "memory":  # preallocated rings + index, per step of capacity
        mem = st["bytes"] / (st["capacity_sequences"] * T)
    else:  # redis-server's own accounting, per stored step (service records + raw blobs so far)
        stored = st["size_sequences"] + reps * ins_batch
        mem = mem_raw / (stored * T)
    med = lambda xs: float(np.median(xs))  # noqa: E731
    ins_sps, smp_sps = ins_batch / med(ins), sample_b / med(smp)
    raw_ins_sps, raw_smp_sps = ins_batch / med(raw_ins), sample_b / med(raw_smp)
    mb = seq_bytes / 1e6
    return {
        "bench": "replay", "obs": kind, "shards": shards, "backend": backend, "seq_len": T,
        "insert_batch": ins_batch, "sample_batch": sample_b, "rounds": reps, "seq_bytes": int(seq_bytes),
        "insert_seq_per_s": round(ins_sps, 1), "insert_mb_per_s": round(ins_sps * mb, 1),
        "sample_seq_per_s": round(smp_sps, 1), "sample_mb_per_s": round(smp_sps * mb, 1),
        "raw": "numpy copy" if backend == "memory" else "redis-py pipelined SET/GET",
        "raw_insert_mb_per_s": round(raw_ins_sps * mb, 1), "raw_sample_mb_per_s": round(raw_smp_sps * mb, 1),
        "insert_vs_raw": round(ins_sps / raw_ins_sps, 3), "sample_vs_raw": round(smp_sps / raw_smp_sps, 3),
        **({"raw_get_only_mb_per_s": round(sample_b / med(raw_bytes) * mb, 1),
            "sample_vs_raw_get_only": round(smp_sps / (sample_b / med(raw_bytes)), 3)} if raw_bytes else {}),
        "bytes_per_stored_step": round(mem, 1), "raw_bytes_per_step": round(raw_step, 1),
        "memory_vs_raw": round(mem / raw_step, 3), "load_avg_1m": round(os.getloadavg()[0], 1),
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
