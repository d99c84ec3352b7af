"""Replay throughput against raw limits measured in the same run.

Cases: vector observations (T=64, 20 float32) and pixels (T=64, 64x64x3 uint8), 1 and 2
shards, three variants side by side: the memory backend through shared memory (`memory`,
the default), the memory backend with `replay.shm` off (`memory-actor`: rows through actor
calls, as for a client on another node) and redis (a private redis-server, appendfsync
everysec). Each reports inserts and samples per second and MB/s through the real service
(Ray actors, limiter off), next to the raw limit for the same bytes: a numpy copy (memory)
or redis-py pipelined SET / GET of one blob per sequence (redis; a raw sample also cuts its
blobs into the batch arrays, and the GET alone is reported too, as is one pipeline reading a
whole round's keys at once: `raw_ahead`, what the service's stock of samples does). Figures
are medians over rounds that alternate every variant at 1 and 2 shards and both raw limits,
so machine load hits all alike (the cyclic GC paused while timing, since its pauses land on
either side at random); each round times a block of back-to-back calls per service
(`calls_per_round`: inserts, samples), so costs paid once every few calls count at their
share. After each observation kind's rows, one row of ratios per shard count (shm / redis,
shm / actor calls) and one of 2-shard / 1-shard sample ratios. Also the memory per stored
step against the raw bytes per step.
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


def _renumbered(batch: SequenceBatch, start: int) -> SequenceBatch:
    """The same arrays under episode ids start.. (inserts need not copy the bytes to differ)."""
    return SequenceBatch(batch.data, batch.mask, batch.version, np.arange(start, start + len(batch), dtype=np.int64))


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


# (label, backend, replay.shm): the default memory backend through shared memory, the same
# backend with shm off (rows through actor calls: what a client on another node gets), redis
VARIANTS = (("memory", "memory", True), ("memory-actor", "memory", False), ("redis", "redis", True))


def _rotated(items: list, i: int) -> list:
    """`items` starting at position i (mod len): round i of the timing loops starts one service
    later, so no service always follows the same one (what ran just before decides how warm the
    caches are: a fixed order biases the ratios)."""
    k = i % len(items)
    return items[k:] + items[:k]


def _cases(kind: str, shard_counts: list[int], quick: bool, run_dir: str) -> list[dict]:
    """Every variant at every shard count on the same batches, their rounds interleaved (so
    load hits all alike): one row per service, one row of ratios per shard count, and one of
    2-shard / 1-shard sample ratios."""
    from wmdist.runtime.replay_client import create_replay

    fields = _fields(kind)
    ins_batch = 32 if kind == "vector" else 8  # sequences per insert call
    sample_b = 32 if kind == "vector" else 16
    reps = (6 if quick else 64) if kind == "vector" else (4 if quick else 24)  # medians of many rounds
    # each round times a block of back-to-back calls per service: a call's costs that come once
    # every few calls (slots reserved ahead, draws asked ahead, a stock gathered for the next
    # samples: `replay/stock.py`) are then inside every figure at their real share
    ins_block = 4 if kind == "vector" else 2
    smp_block = 32 if kind == "vector" else 4
    # the actor-call path has no stock or draws ahead to spread; a short block keeps its ~4 ms
    # calls from stretching every round (draws older than 1 s are dropped: `MAX_DRAW_AGE`)
    smp_blocks = {"memory-actor": 4}
    inserts = reps * ins_block + 1
    # 8x what the rounds insert: a shard holds well over 16 inserts' worth, so a client's
    # reservations ahead (at most 1/16 of a shard) cover several inserts, as in any real-sized
    # buffer (1M steps by default); only written rows take memory
    capacity_seq = ins_batch * inserts * 8
    rng = np.random.default_rng(0)
    distinct = [_batch(fields, ins_batch, 0, rng) for _ in range(4)]  # arrays shared by the inserts
    batches = [_renumbered(distinct[i % 4], i * ins_batch) for i in range(inserts)]
    seq_bytes = batches[0].nbytes / ins_batch
    services = [(label, backend, shm, S) for S in shard_counts for label, backend, shm in VARIANTS]
    clients: dict[tuple[str, int], object] = {}
    raws: dict = {}
    ins: dict = {}
    smp: dict = {}
    stats, used = {}, {}
    try:
        for label, backend, shm, S in services:
            cfg = ReplayConfig(backend=backend, shards=S, capacity_steps=capacity_seq * T, seq_len=T, min_size=0,
                               samples_per_insert=0, shard_cpus=0.1, shm=shm)
            name = f"bench-{kind}-{S}-{label}"  # its own directory: a private redis-server each
            clients[label, S] = create_replay(cfg, fields, os.path.join(run_dir, name), name)
        servers = {key: c._server.client() for key, c in clients.items() if key[0] == "redis"}
        rc = servers["redis", shard_counts[0]]  # the raw redis limit runs on this one's server
        used = {key: r.info("memory")["used_memory"] for key, r in servers.items()}
        for c in clients.values():
            c.insert(batches[-1], source_id=0)  # warm up actors, connections and mappings
            for _ in range(smp_block):
                c.sample(sample_b)
        raws = {"raw_numpy": _RawNumpy(batches[0], capacity_seq), "raw_redis": _RawRedis(rc, batches[0])}
        # rounds alternate every service and both raw limits on the same bytes, so load noise hits
        # all; the cyclic GC is paused while timing (its pauses land on any side at random)
        gc.collect()
        gc.disable()
        for k in [*clients, *raws, "raw_redis_get", "raw_redis_ahead"]:
            ins[k], smp[k] = [], []
        order = list(clients.items())

        def block(fn, n: int) -> float:  # seconds per call over n back-to-back calls
            return _time(lambda: [fn(j) for j in range(n)]) / n

        for i in range(reps):
            at = i * ins_block
            for key, c in _rotated(order, i):
                ins[key].append(block(lambda j: c.insert(batches[at + j], source_id=at + j), ins_block))
            for k, raw in raws.items():
                ins[k].append(block(lambda j: raw.put(batches[at + j], at + j), ins_block))
        stats = {key: c.stats() for key, c in clients.items()}
        used = {key: r.info("memory")["used_memory"] - used[key] for key, r in servers.items()}
        for i in range(reps):
            at = i * smp_block
            for key, c in _rotated(order, i):
                smp[key].append(block(lambda j: c.sample(sample_b), smp_blocks.get(key[0], smp_block)))
            for k, raw in raws.items():
                smp[k].append(block(lambda j: raw.get(sample_b, at + j), smp_block))
            smp["raw_redis_get"].append(block(lambda j: raws["raw_redis"].get_bytes(sample_b, at + j), smp_block))
            # the raw limit reading a block's keys in one pipeline, as the service's stock does
            smp["raw_redis_ahead"].append(_time(lambda: raws["raw_redis"].get(sample_b * smp_block, i)) / smp_block)
    finally:
        gc.enable()
        if "raw_redis" in raws:
            raws["raw_redis"].close()
        for c in clients.values():
            c.close()
    med = lambda xs: float(np.median(xs))  # noqa: E731
    ins_sps = {k: ins_batch / med(v) for k, v in ins.items() if v}
    smp_sps = {k: sample_b / med(v) for k, v in smp.items() if v}
    mb, raw_step = seq_bytes / 1e6, seq_bytes / T  # raw bytes per step: fields + 1-byte mask
    load = round(os.getloadavg()[0], 1)
    rows = []
    for label, backend, _, S in services:
        key, st = (label, S), stats[label, S]
        raw = "raw_numpy" if backend == "memory" else "raw_redis"
        if backend == "memory":  # preallocated rings + index, per step of capacity
            mem = st["bytes"] / (st["capacity_sequences"] * T)
        else:  # redis-server's own accounting, per stored step (service records, + raw blobs on rc's)
            blobs = reps * ins_block * ins_batch if S == shard_counts[0] else 0
            mem = used[key] / ((st["size_sequences"] + blobs) * T)
        rows.append({
            "bench": "replay", "obs": kind, "shards": S, "backend": label, "seq_len": T,
            "insert_batch": ins_batch, "sample_batch": sample_b, "rounds": reps,
            "calls_per_round": [ins_block, smp_blocks.get(label, smp_block)],
            "seq_bytes": int(seq_bytes),
            "insert_seq_per_s": round(ins_sps[key], 1), "insert_mb_per_s": round(ins_sps[key] * mb, 1),
            "sample_seq_per_s": round(smp_sps[key], 1), "sample_mb_per_s": round(smp_sps[key] * mb, 1),
            "raw": "numpy copy" if raw == "raw_numpy" else "redis-py pipelined SET/GET",
            "raw_insert_mb_per_s": round(ins_sps[raw] * mb, 1), "raw_sample_mb_per_s": round(smp_sps[raw] * mb, 1),
            "insert_vs_raw": round(ins_sps[key] / ins_sps[raw], 3),
            "sample_vs_raw": round(smp_sps[key] / smp_sps[raw], 3),
            **({"raw_get_only_mb_per_s": round(smp_sps["raw_redis_get"] * mb, 1),
                "sample_vs_raw_get_only": round(smp_sps[key] / smp_sps["raw_redis_get"], 3),
                "raw_ahead_sample_mb_per_s": round(smp_sps["raw_redis_ahead"] * mb, 1),
                "sample_vs_raw_ahead": round(smp_sps[key] / smp_sps["raw_redis_ahead"], 3)}
               if raw == "raw_redis" else {}),
            **({"stale_reads": int(st.get("stale_reads", 0))} if label == "memory" else {}),
            "bytes_per_stored_step": round(mem, 1), "raw_bytes_per_step": round(raw_step, 1),
            "memory_vs_raw": round(mem / raw_step, 3), "load_avg_1m": load,
        })
    def ins_ratio(a: tuple, b: tuple) -> float:
        return round(ins_sps[a] / ins_sps[b], 3)

    def smp_ratio(a: tuple, b: tuple) -> float:
        return round(smp_sps[a] / smp_sps[b], 3)

    for S in shard_counts:
        rows.append({
            "bench": "replay", "obs": kind, "shards": S, "compare": "memory (shm) / redis, memory (shm) / actor calls",
            "insert_shm_vs_redis": ins_ratio(("memory", S), ("redis", S)),
            "sample_shm_vs_redis": smp_ratio(("memory", S), ("redis", S)),
            "insert_shm_vs_actor": ins_ratio(("memory", S), ("memory-actor", S)),
            "sample_shm_vs_actor": smp_ratio(("memory", S), ("memory-actor", S)),
            "load_avg_1m": load,
        })
    if 1 in shard_counts and 2 in shard_counts:  # two shards should sample at least as fast as one
        rows.append({"bench": "replay", "obs": kind, "compare": "sample, 2 shards / 1 shard",
                     **{f"sample_2_vs_1_{label}": smp_ratio((label, 2), (label, 1)) for label, _, _ in VARIANTS}})
    return rows


def run(quick: bool = False) -> Iterator[dict]:
    import ray

    started = not ray.is_initialized()
    if started:
        ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        with tempfile.TemporaryDirectory(prefix="wmdist-bench-replay-") as run_dir:
            for kind in ["vector"] if quick else ["vector", "pixels"]:
                yield from _cases(kind, [1] if quick else [1, 2], quick, run_dir)
    finally:
        if started:
            ray.shutdown()
