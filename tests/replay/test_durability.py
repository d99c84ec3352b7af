"""Durability and recovery without Ray: redis SIGKILL under appendfsync always, corrupt records,
memory checkpoints, and the memory overhead of the ring storage."""
from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest
from replay_helpers import FIELDS, T, make_batch

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.redis_server import RedisServer
from wmdist.replay.shard import ReplayShard
from wmdist.replay.storage_redis import (RecordsMissing, RedisStorage, commit_records, encode_rows, new_keys,
                                         pending_entry, put_records)


def _redis_shard(server: RedisServer, ns: str, capacity: int = 16, sampler: str = "prioritized") -> ReplayShard:
    return ReplayShard(FIELDS, T, capacity, sampler, 1.0, RedisStorage(FIELDS, capacity, T, server.client(), ns))


def _contents(sh: ReplayShard) -> dict[int, np.ndarray]:
    live = np.flatnonzero(sh.stamp >= 0)
    data, mask, bad = sh.storage.read(live) if sh.storage.durable else (
        {k: v[live] for k, v in sh.storage.data.items()}, sh.storage.mask[live], [])
    return {int(s): (data["obs"][i], data["root_value"][i], mask[i]) for i, s in enumerate(live)}


def test_acknowledged_sequences_survive_redis_sigkill(tmp_path):
    server = RedisServer(str(tmp_path), appendfsync="always").start()
    try:
        sh = _redis_shard(server, "wmdist:dur:s0")
        for start in range(0, 12, 3):  # each insert returns only after MULTI/EXEC was acknowledged
            sh.insert(make_batch(3, start=start, steps=np.array([T, 5, 2])))
        s = sh.sample(4)
        sh.update_priorities(s["slots"], s["stamps"], np.array([3.0, 4.0, 5.0, 6.0]))
        sh.write_back(s["slots"][:1], s["stamps"][:1], {"root_value": np.full((1, T), 9.0, np.float32)})
        before, prio, stamps = _contents(sh), sh.priority.copy(), sh.stamp.copy()
        server.kill()  # SIGKILL: only what the AOF holds survives
        server.start()
        sh2 = _redis_shard(server, "wmdist:dur:s0")  # a restarted shard rebuilds its index
        assert np.array_equal(sh2.stamp, stamps) and np.allclose(sh2.priority, prio)
        after = _contents(sh2)
        assert after.keys() == before.keys() and len(after) == 12
        for k in before:
            assert all(np.array_equal(a, b) for a, b in zip(before[k], after[k]))
        assert sh2.stats()["size_steps"] == 4 * (T + 7) and sh2.count == 12
        sh2.insert(make_batch(1, start=50))  # and it serves again, continuing the ring
        assert sh2.stamp[12] == 12 and sh2.sample(4)["data"]["obs"].shape == (4, T, 3)
        # the original shard's connection recovers too
        assert sh.sample(2)["data"]["obs"].shape == (2, T, 3)
    finally:
        server.stop()


def test_corrupt_records_are_skipped_and_counted(redis_server, namespace):
    sh = _redis_shard(redis_server, namespace, capacity=8, sampler="uniform")
    sh.insert(make_batch(7))
    r = redis_server.client()
    key = sh.storage.keys
    r.set(key[1], b"\x93garbage")
    raw = r.get(key[2])
    r.set(key[2], raw[:-5])  # truncated
    r.set(key[3], raw.replace(b"float32", b"float64", 1))  # dtype no longer matches the bytes
    r.hset(f"{namespace}:idx", 6, b"\xc1")  # a corrupt index entry
    r.set(f"{namespace}:r:never-acked", raw)  # written by an insert that never reached the index
    sh2 = _redis_shard(redis_server, namespace, capacity=8, sampler="uniform")
    st = sh2.stats()
    # slot 6's record lost its index entry, so it is unreferenced like the never-acked one
    assert st["drops_corrupt"] == 4 and st["drops_unacked"] == 2 and st["size_sequences"] == 3
    assert r.get(f"{namespace}:r:never-acked") is None and r.get(key[6]) is None
    assert set(sh2.sample(100)["data"]["obs"][:, 0, 0].astype(int)) == {0, 4, 5}
    # corrupted under a running shard: found at sample time, skipped, counted, still serving
    r.set(key[4], b"\x00")
    s = sh2.sample(300)
    assert set(s["data"]["obs"][:, 0, 0].astype(int)) == {0, 5} and sh2.stats()["drops_corrupt"] == 5
    sh2.insert(make_batch(3, start=20))  # the ring goes on: slots 7, 0 (evicts seq 0), 1
    assert sh2.stats()["size_sequences"] == 4 and sh2.stats()["drops_evicted"] == 1


def test_direct_insert_straddling_a_shard_restart_is_refused_not_lost(redis_server, namespace):
    sh = _redis_shard(redis_server, namespace, capacity=8)
    b = make_batch(2)
    keys = new_keys(namespace, 2)
    put_records(redis_server.client(), dict(zip(keys, encode_rows(b, np.arange(2)))))  # client wrote...
    restarted = _redis_shard(redis_server, namespace, capacity=8)  # ...the shard restarted...
    assert restarted.stats()["drops_unacked"] == 2  # ...and removed the unindexed records
    with pytest.raises(RecordsMissing):  # so indexing them now is refused (the client writes again)
        restarted.insert_keys(keys, b.version, b.episode_id, b.mask.sum(1), lag_drops=1)
    assert restarted.stats()["size_sequences"] == 0 and restarted.stats()["drops_policy_lag"] == 0
    keys = new_keys(namespace, 2)
    put_records(redis_server.client(), dict(zip(keys, encode_rows(b, np.arange(2)))))
    assert restarted.insert_keys(keys, b.version, b.episode_id, b.mask.sum(1), lag_drops=1) == 2 * T
    assert _redis_shard(redis_server, namespace, capacity=8).stats()["size_sequences"] == 2


def _announce(r, ns: str, batch: SequenceBatch, lag: int = 0) -> list[str]:
    """A client's insert: the records, then its pending entry (`commit_records`; acknowledged)."""
    keys = new_keys(ns, len(batch))
    entry = pending_entry(keys, batch.version, batch.episode_id, batch.mask.sum(1), lag)
    commit_records(r, [(ns, dict(zip(keys, encode_rows(batch, np.arange(len(batch))))), entry)])
    return keys


def test_insert_acknowledged_before_indexing_survives_redis_and_shard_restart(tmp_path):
    server = RedisServer(str(tmp_path), appendfsync="always").start()
    try:
        ns = "wmdist:ack:s0"
        sh = _redis_shard(server, ns, capacity=8)
        sh.insert(make_batch(2))  # indexed
        _announce(server.client(), ns, make_batch(3, start=10, steps=np.array([T, 4, 1])))
        assert sh.size_sequences == 2  # acknowledged, but the shard has not indexed it yet
        server.kill()  # SIGKILL redis-server, then a fresh shard process: both restart
        server.start()
        sh2 = _redis_shard(server, ns, capacity=8)
        st = sh2.stats()
        assert st["size_sequences"] == 5 and st["size_steps"] == 3 * T + 5 and st["drops_unacked"] == 0
        assert set(sh2.sample(300)["data"]["obs"][:, 0, 0].astype(int)) == {0, 1, 10, 11, 12}
        assert server.client().llen(f"{ns}:pending") == 0
        sh3 = _redis_shard(server, ns, capacity=8)  # indexed exactly once
        assert sh3.stats()["size_sequences"] == 5 and np.array_equal(sh3.stamp, sh2.stamp) and sh3.count == 5
    finally:
        server.stop()


def test_pending_entries_are_indexed_once_with_eviction_lag_and_bad_entries(redis_server, namespace):
    r = redis_server.client()
    sh = _redis_shard(redis_server, namespace, capacity=8, sampler="uniform")
    k1 = _announce(r, namespace, make_batch(5))
    r.rpush(f"{namespace}:pending", b"\xc1")  # a malformed entry
    k2 = _announce(r, namespace, make_batch(6, start=5), lag=2)
    st = sh.stats()  # every read indexes what was announced before it
    assert st["size_sequences"] == 8 and st["inserts"] == 11 and st["drops_evicted"] == 3
    assert st["drops_corrupt"] == 1 and st["drops_policy_lag"] == 2 and r.llen(f"{namespace}:pending") == 0
    assert set(sh.sample(400)["data"]["obs"][:, 0, 0].astype(int)) == set(range(3, 11))
    assert [r.exists(k) for k in k1 + k2] == [0] * 3 + [1] * 8  # the evicted ones' records are gone
    assert sh.drain() == 0 and sh.stats()["inserts"] == 11  # nothing indexed twice


def test_memory_checkpoint_restores_exactly(tmp_path):
    a = ReplayShard(FIELDS, T, 8, "prioritized", 0.6, seed=3)
    a.insert(make_batch(11, steps=np.arange(11) % T + 1))  # wraps the ring: 3 evicted
    s = a.sample(5)
    a.update_priorities(s["slots"], s["stamps"], np.arange(5) + 0.5)
    a.save(str(tmp_path / "shard0.npz"))
    b = ReplayShard(FIELDS, T, 8, "prioritized", 0.6, seed=3)
    b.restore(str(tmp_path / "shard0.npz"))
    for k, v in a.storage.arrays().items():
        assert np.array_equal(v, b.storage.arrays()[k]), k
    for k in ("stamp", "version", "episode", "steps", "priority"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert np.array_equal(a.tree.tree, b.tree.tree) and a.stats() == b.stats() and a.count == b.count
    with pytest.raises(ValueError, match="capacity"):
        ReplayShard(FIELDS, T, 9).restore(str(tmp_path / "shard0.npz"))


def test_memory_overhead_within_ten_percent():
    fields = {"obs": FieldSpec((20,), "float32"), "action": FieldSpec((), "int64"),
              "reward": FieldSpec((), "float32"), "first": FieldSpec((), "bool"),
              "last": FieldSpec((), "bool"), "terminal": FieldSpec((), "bool")}
    seq_len, capacity = 64, 2000
    raw_per_step = sum(int(np.prod(s.shape)) * np.dtype(s.dtype).itemsize for s in fields.values())
    n = 500
    batch = SequenceBatch({k: np.ones((n, seq_len, *s.shape), s.dtype) for k, s in fields.items()},
                          np.ones((n, seq_len), bool), np.zeros(n, np.int64), np.arange(n))
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    sh = ReplayShard(fields, seq_len, capacity, "prioritized")
    for _ in range(capacity // n + 1):  # fill (and wrap) the whole ring
        sh.insert(batch)
    used = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    raw = capacity * seq_len * raw_per_step
    assert sh.size_sequences == capacity
    assert raw <= used <= 1.10 * raw, (used, raw)


def test_a_young_runs_checkpoint_holds_its_rows_not_the_whole_buffer(tmp_path):
    """A 4,096-slot ring with 3 sequences in it checkpoints 3 rows (not 4,096 of zeros), and a
    shard restored from it holds the same rows; a full ring still saves every row."""
    big = 4096
    a = ReplayShard(FIELDS, T, big, "uniform")
    a.insert(make_batch(3))
    path = tmp_path / "young.npz"
    a.save(str(path))
    with np.load(path, allow_pickle=False) as z:
        assert {len(z[k]) for k in z.files if k.startswith("f_") or k == "mask"} == {3}
    b = ReplayShard(FIELDS, T, big, "uniform")
    b.restore(str(path))
    for k, v in a.storage.arrays().items():
        assert np.array_equal(v[:3], b.storage.arrays()[k][:3]), k
    assert a.stats() == b.stats()
    full = ReplayShard(FIELDS, T, 8, "uniform")
    full.insert(make_batch(11))
    full.save(str(tmp_path / "full.npz"))
    with np.load(tmp_path / "full.npz", allow_pickle=False) as z:
        assert len(z["mask"]) == 8
