"""The Ray service end to end (real Ray, real redis-server): shards sampled as one buffer, the
shared limiter, close, checkpoints, private redis-server, and SIGKILL of a shard process."""
from __future__ import annotations

import os
import pickle
import signal
import stat
import threading
import time

import numpy as np
import pytest
import ray
import redis
from replay_helpers import T, make_batch, sample_ids, wait_shard_restarted
from scipy.stats import chisquare

from wmdist.replay.config import ReplayConfig
from wmdist.runtime import replay_client


def _cfg(**kw) -> ReplayConfig:
    base = dict(shards=2, capacity_steps=64 * T, seq_len=T, min_size=0, shard_cpus=0.1, error_buffer=1000)
    return ReplayConfig(**{**base, **kw})


@pytest.mark.parametrize("backend", ["memory", "redis"])
def test_two_shards_sample_as_one_buffer(started, backend):
    c = started(_cfg(backend=backend, sampler="prioritized", priority_alpha=1.0, priority_beta=0.5))
    for src in range(4):  # 4 collectors x 5 episodes, routed by hash(collector, episode)
        b = make_batch(5, start=5 * src)
        assert c.insert(b, source_id=src)
    st = c.stats()
    assert st["size_sequences"] == 20 and min(st["shard0_size_sequences"], st["shard1_size_sequences"]) > 0
    # uniform at first (all at max priority): every sequence equally likely across both shards
    ids = np.concatenate([sample_ids(c.sample(500)) for _ in range(8)])
    assert chisquare(np.bincount(ids, minlength=20)).pvalue > 1e-3
    # priorities p_i = i + 1 written back by key: frequencies and IS weights follow the union
    seen = {}
    for _ in range(10):  # collect (key, stamp) of every sequence from what sampling returns
        s = c.sample(100)
        seen.update({i: (k, st_) for k, st_, i in zip(s.keys, s.stamps, sample_ids(s))})
    assert len(seen) == 20
    keys = np.array([seen[i][0] for i in range(20)])
    stamps = np.array([seen[i][1] for i in range(20)])
    assert c.update_priorities(keys, stamps, np.arange(1, 21, dtype=float)) == 20
    samples = [c.sample(500) for _ in range(8)]
    ids = np.concatenate([sample_ids(x) for x in samples])
    P = np.arange(1, 21) / np.arange(1, 21).sum()
    assert chisquare(np.bincount(ids, minlength=20), P * ids.size).pvalue > 1e-3
    x = samples[0]
    w = (20 * P[sample_ids(x)]) ** -0.5
    assert np.allclose(x.is_weight, w / w.max(), rtol=1e-5)


def test_limiter_held_across_shards(started):
    c = started(_cfg(samples_per_insert=2.0, error_buffer=4, min_size=3 * T))
    assert c.sample(2, timeout=0.2) is None  # below min_size
    assert c.insert(make_batch(3), source_id=0)
    got = c.sample(2, timeout=5)
    assert got is not None and got.data["obs"].shape == (2, T, 3) and got.mask.dtype == np.float32
    for _ in range(2):  # samples run ahead of the ratio: the next one waits
        assert c.sample(2, timeout=5) is not None
    assert c.sample(2, timeout=0.3) is None
    assert c.insert(make_batch(3, start=10), source_id=1)
    assert c.sample(2, timeout=5) is not None
    # inserts that run ahead wait too (both shards count against one limiter)
    oks = [c.insert(make_batch(1, start=20 + i), source_id=i, timeout=0.2) for i in range(12)]
    assert oks.count(False) > 0 and oks[0]
    st = c.stats()
    assert st["sample_wait_seconds"] >= 0.4 and st["insert_wait_seconds"] > 0.1


@pytest.mark.parametrize("backend", ["memory", "redis"])
def test_held_counts_are_sent_before_anything_reads_or_waits_on_them(started, backend):
    """Ratio off: insert counts are coalesced on the caller's thread (no timer), and a sample
    waiting for min_size, stats and a copy's close send what this copy still holds."""
    c = started(_cfg(backend=backend, min_size=4 * T))
    assert c.insert(make_batch(2), source_id=0)  # the first count goes at once
    c._inserts.every = 3600.0  # from now on held until something flushes (no timer would send them)
    assert c.insert(make_batch(2, start=2), source_id=1)
    assert c._inserts.pending == (2, 2 * T)
    assert c.sample(3, timeout=5) is not None  # min_size needs both inserts: sent before waiting
    for i in range(5):
        assert c.insert(make_batch(1, start=4 + i), source_id=i)
    assert c._inserts.pending == (5, 5 * T)
    assert c.stats()["limiter_inserted"] == 9  # nothing left held behind stats
    copy = pickle.loads(pickle.dumps(c))
    for i in range(2):
        assert copy.insert(make_batch(1, start=9 + i), source_id=i)
    copy.close()
    assert c.stats()["limiter_inserted"] == 11 and c.stats()["limiter_size_steps"] == 11 * T


def test_close_unblocks_waiters_and_checkpoint_round_trip(started, tmp_path):
    # min_size at the whole capacity: the 9 sequences inserted below never let the waiter sample
    c = started(_cfg(shards=1, min_size=64 * T, sampler="prioritized"))
    out = []
    th = threading.Thread(target=lambda: out.append(c.sample(4, timeout=None)))
    th.start()
    assert c.insert(make_batch(6), source_id=3)
    pickled = pickle.loads(pickle.dumps(c))  # what collectors receive
    assert pickled.insert(make_batch(2, start=6), source_id=4)
    c.save(str(tmp_path / "ckpt"))
    time.sleep(0.2)
    assert th.is_alive()
    c2 = started(_cfg(shards=1, min_size=64 * T, sampler="prioritized"), name="t2")
    c2.restore(str(tmp_path / "ckpt"))
    a, b = c.stats(), c2.stats()
    for k in ("size_sequences", "size_steps", "inserts", "shard0_size_sequences", "limiter_size_steps"):
        assert a[k] == b[k], k
    pickled.close()  # a copy's close stops only that copy
    assert not pickled.insert(make_batch(1, start=40), source_id=4)
    assert c.insert(make_batch(1, start=41), source_id=5) and th.is_alive()
    c.close()
    th.join(10)
    assert not th.is_alive() and out == [None]
    assert c.sample(1, timeout=0.1) is None and not c.insert(make_batch(1), 0)


def test_policy_lag_and_bad_input(started):
    c = started(_cfg(shards=1, max_policy_lag=2))
    c.set_policy_version(5)
    b = make_batch(5)  # versions 0..4: only 3 and 4 are within 2 of version 5
    assert c.insert(b, source_id=0)
    st = c.stats()
    assert st["drops_policy_lag"] == 3 and st["size_sequences"] == 2
    bad = make_batch(2)
    bad.data["obs"] = bad.data["obs"][..., :2]
    with pytest.raises(ValueError, match="'obs': shape"):
        c.insert(bad, source_id=0)


def test_private_redis_and_shard_sigkill(started, tmp_path):
    c = started(_cfg(backend="redis", redis_appendfsync="always", sampler="prioritized"), name="dur")
    server = c._server
    pw = os.path.join(server.dir, "redis.pass")
    assert stat.S_IMODE(os.stat(pw).st_mode) == 0o600
    assert stat.S_IMODE(os.stat(server.conf).st_mode) == 0o600
    with pytest.raises(redis.AuthenticationError):
        redis.Redis(port=server.port).ping()  # a password is required
    assert server.client().config_get("bind")["bind"] == "127.0.0.1"
    for src in range(3):
        assert c.insert(make_batch(4, start=4 * src), source_id=src)
    s = c.sample(12)
    c.update_priorities(s.keys, s.stamps, np.full(12, 2.5))
    before = c.stats()
    # SIGKILL redis-server, restart it from its AOF, then SIGKILL a shard process
    server.kill()
    server.start()
    pid = ray.get(c.shards[0].pid.remote())
    os.kill(pid, signal.SIGKILL)
    wait_shard_restarted(c, pid)
    after = c.stats()
    for k in ("size_sequences", "size_steps", "shard0_size_sequences", "shard1_size_sequences"):
        assert after[k] == before[k], k
    ids = np.concatenate([sample_ids(c.sample(64)) for _ in range(3)])
    assert set(ids) == set(range(12))  # every acknowledged sequence is served again
    # records broken or lost behind the service's back: redrawn, dropped and counted
    r = server.client()
    keys = sorted(k for k in r.scan_iter(match="wmdist:dur:s*:r:*"))
    r.set(keys[0], b"\x00")
    r.delete(keys[1])
    for _ in range(3):
        x = c.sample(64)
        assert np.all(x.mask.sum(1) == T) and np.all(x.data["obs"][:, :, 1] == np.arange(T))
    assert c.stats()["drops_corrupt"] == 2 and c.stats()["size_sequences"] == 10
    d = server.dir
    c.close()
    assert server.proc is None and not any(f.endswith(".pid") for f in os.listdir(d))


def test_redis_inserts_need_no_shard_and_survive_its_restart(started):
    c = started(_cfg(backend="redis", shards=1, redis_appendfsync="always"), name="down")
    assert c.insert(make_batch(3), source_id=0)
    pid = ray.get(c.shards[0].pid.remote())
    os.kill(pid, signal.SIGKILL)
    # acknowledged by redis alone while the shard is dead or rebuilding: nothing waits for it
    assert c.insert(make_batch(3, start=3), source_id=1)
    wait_shard_restarted(c, pid)
    st = c.stats()
    assert st["size_sequences"] == 6 and st["drops_unacked"] == 0 and st["limiter_size_steps"] == 6 * T
    assert set(sample_ids(c.sample(300))) == set(range(6))
    with pytest.raises(ValueError, match="no real step"):  # refused before anything is written
        c.insert(make_batch(1, start=9, steps=np.array([0])), source_id=2)


def test_redis_insert_swept_before_its_announcement_is_written_again(started, monkeypatch):
    """A shard restart can sweep an insert's records between its SETs and its announcement:
    the announcement is refused and the client writes the records again, under new keys."""
    from wmdist.replay import storage_redis

    c = started(_cfg(backend="redis", shards=1), name="swept")
    refused = []

    def commit_swept_once(r, writes):
        if refused:
            return storage_redis.commit_records(r, writes)
        ns, recs, entry = writes[0]
        storage_redis.put_records(r, recs)
        r.delete(next(iter(recs)))  # the sweep of a restarting shard
        refused.append(list(recs))
        assert r.eval(storage_redis._ANNOUNCE, len(recs) + 1, *recs, f"{ns}:pending", entry) == 0
        return [0]

    monkeypatch.setattr(replay_client, "commit_records", commit_swept_once)
    assert c.insert(make_batch(4), source_id=0)
    st = c.stats()
    assert refused and st["size_sequences"] == 4 and st["drops_corrupt"] == 0
    assert set(sample_ids(c.sample(200))) == set(range(4))
    left = [k.decode() for k in c.redis.scan_iter(match=f"{c._namespaces[0]}:r:*")]
    assert len(left) == 4 and not set(left) & set(refused[0])  # the first attempt left nothing


def test_redis_sample_sees_own_writes_and_redraws_stale_draws(started, monkeypatch):
    monkeypatch.setattr(replay_client, "MAX_DRAW_AGE", 600.0)  # pooled draws stay usable however slow the machine
    c = started(_cfg(backend="redis", capacity_steps=24 * T), name="rw")  # 2 shards x 12 slots
    other = pickle.loads(pickle.dumps(c))  # another process's client
    assert c.insert(make_batch(6), source_id=0)
    for _ in range(3):  # stocks the draw pools (draws for later calls in flight)
        assert set(sample_ids(c.sample(8))) <= set(range(6))
    assert c.insert(make_batch(6, start=6), source_id=1)  # this copy's write: its next sample sees it
    assert set(sample_ids(c.sample(300))) == set(range(12))
    old = c.sample(8)
    c.sample(8)
    for i in range(4):  # another copy evicts every sequence c's pooled draws point at
        assert other.insert(make_batch(16, start=100 + 16 * i), source_id=7 + i)
    assert other.stats()["size_sequences"] == 24  # a read: the shards have indexed (and evicted) by now
    x = c.sample(64)  # pooled draws name evicted records: drawn again, not counted as corrupt
    assert set(sample_ids(x)) <= set(range(100, 164)) and np.all(x.data["obs"][:, :, 1] == np.arange(T))
    st = c.stats()
    assert st["drops_corrupt"] == 0 and st["size_sequences"] == 24
    assert c.update_priorities(old.keys, old.stamps, np.ones(8)) == 0  # stamps still catch stale write-backs
    assert c.stats()["drops_stale_priority"] == 8


@pytest.mark.parametrize("backend", ["memory", "redis"])
def test_samples_carry_each_steps_age_and_beta_anneals(started, backend):
    """Ages (transitions stored after each step) reach the sampler on both paths; beta rises
    from priority_beta to 1 over priority_beta_anneal_samples learner batches."""
    c = started(_cfg(backend=backend, shards=1, sampler="prioritized", priority_alpha=1.0, priority_beta=0.0,
                     priority_beta_anneal_samples=2), name=f"age{backend}")
    steps = [T, 3, 5]
    assert c.insert(make_batch(3, steps=np.array(steps)), source_id=0)
    order = [(i, t) for i, n in enumerate(steps) for t in range(n)]  # storage order
    want = {(i, t): len(order) - 1 - k for k, (i, t) in enumerate(order)}
    s = c.sample(64, limited=False)
    for row, i in enumerate(sample_ids(s)):
        assert s.age[row, :steps[i]].tolist() == [want[(i, t)] for t in range(steps[i])]
    keys = {i: (k, st) for k, st, i in zip(s.keys, s.stamps, sample_ids(s))}
    assert c.update_priorities(np.array([keys[i][0] for i in range(3)]), np.array([keys[i][1] for i in range(3)]),
                               np.array([1.0, 2.0, 4.0])) == 3
    assert np.allclose(c.sample(64).is_weight, 1.0)  # beta 0 at the first learner batch
    c.sample(64)
    x = c.sample(64)  # two batches done: beta = 1
    w = (3 * np.array([1.0, 2.0, 4.0])[sample_ids(x)] / 7.0) ** -1.0
    assert np.allclose(x.is_weight, w / w.max(), rtol=1e-5)
