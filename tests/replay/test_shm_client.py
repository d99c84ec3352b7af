"""The memory backend through shared memory, end to end on a real local Ray: exact reads,
a row rewritten during a read, a SIGKILLed shard, a collector killed before its commit,
stale write-backs, segment lifetime (swept at a fresh start, unlinked at close), and the
actor-call fallback."""
from __future__ import annotations

import os
import pickle
import signal

import numpy as np
import pytest
import ray
from replay_helpers import FIELDS, T, make_batch, sample_ids, wait_shard_restarted

from wmdist.replay.config import ReplayConfig
from wmdist.replay.shm import SHM_DIR, ShmSegment, segment_prefix
from wmdist.runtime import replay_shm


def _cfg(**kw) -> ReplayConfig:
    base = dict(backend="memory", shards=1, capacity_steps=64 * T, seq_len=T, min_size=0, shard_cpus=0.1)
    return ReplayConfig(**{**base, **kw})


def _segments(tmp_path, name: str) -> list[str]:
    prefix = segment_prefix(name, str(tmp_path))
    return sorted(n for n in os.listdir(SHM_DIR) if n.startswith(prefix))


def _check_rows(sample, inserted: dict) -> None:
    """Every sampled row equals the inserted window with its id, field by field."""
    for row, i in enumerate(sample_ids(sample)):
        b, r = inserted[i]
        assert np.array_equal(sample.mask[row], b.mask[r].astype(np.float32))
        for f in FIELDS:
            assert np.array_equal(sample.data[f][row], b.data[f][r]), f


def test_shm_reads_return_exactly_the_inserted_arrays(started, tmp_path):
    prefix = segment_prefix("exact", str(tmp_path))
    stale = ShmSegment.open(prefix + "s3", FIELDS, 4, T, 1)  # left by an earlier start with 4 shards
    c = started(_cfg(shards=2, sampler="prioritized", priority_alpha=1.0), name="exact")
    stale.close()  # (swept by the fresh start: only this service's segments are left)
    inserted = {}
    for src in range(4):
        b = make_batch(5, start=5 * src, steps=np.array([T, 1, 3, T, 5]))
        inserted.update({5 * src + r: (b, r) for r in range(5)})
        assert c.insert(b, source_id=src)
    assert c._shm is not None and not c._shm.broken  # both shards mapped here, rows written in place
    st = c.stats()
    assert st["size_sequences"] == 20 and min(st["shard0_size_sequences"], st["shard1_size_sequences"]) > 0
    seen = set()
    for _ in range(5):
        s = c.sample(64)
        _check_rows(s, inserted)
        seen |= set(sample_ids(s))
    assert seen == set(range(20)) and c.stats()["stale_reads"] == 0
    assert _segments(tmp_path, "exact") == [prefix + "s0", prefix + "s1"]
    other = pickle.loads(pickle.dumps(c))  # another process's client maps the segments itself
    _check_rows(other.sample(32), inserted)
    other.close()
    c.close()
    assert _segments(tmp_path, "exact") == []  # unlinked at close


def test_a_row_rewritten_during_the_read_is_drawn_again(started, monkeypatch):
    """Deterministic interleaving: between this client's copy and its re-check, another
    client's insert evicts every row it drew; all are drawn again and counted."""
    c = started(_cfg(capacity_steps=32 * T), name="seqlock")
    assert c.insert(make_batch(32), source_id=0)
    other = pickle.loads(pickle.dumps(c))
    real = replay_shm.read_rows
    calls = []

    def read_then_overwrite(rows, shard_of, slots, stamps, out, mask_out, on_copied=None, at=None):
        if calls:
            return real(rows, shard_of, slots, stamps, out, mask_out, at=at)
        calls.append(len(slots))
        return real(rows, shard_of, slots, stamps, out, mask_out, at=at,
                    on_copied=lambda: other.insert(make_batch(40, start=100), source_id=1))

    monkeypatch.setattr(replay_shm, "read_rows", read_then_overwrite)
    x = c.sample(8)
    assert calls == [8] and set(sample_ids(x)) <= set(range(100, 140))
    assert np.all(x.data["obs"][:, :, 1] == np.arange(T)) and np.all(x.data["action"] // 10 == sample_ids(x)[:, None])
    assert c.stats()["stale_reads"] == 8
    other.close()


def test_sigkilled_shard_keeps_every_acknowledged_sequence(started):
    c = started(_cfg(sampler="prioritized", priority_alpha=1.0), name="kill")
    inserted = {}
    for src in range(3):
        b = make_batch(4, start=4 * src)
        inserted.update({4 * src + r: (b, r) for r in range(4)})
        assert c.insert(b, source_id=src)
    s = c.sample(64)
    keys = {i: (k, st) for k, st, i in zip(s.keys, s.stamps, sample_ids(s))}
    k = np.array([keys[i][0] for i in range(12)])
    st = np.array([keys[i][1] for i in range(12)])
    assert c.update_priorities(k, st, np.arange(12) + 1.0) == 12
    assert c.write_back(k[:1], st[:1], {"root_value": np.full((1, T), 5.0, np.float32)}) == 1
    by_call = pickle.loads(pickle.dumps(c))
    by_call._shm_tried = True  # this copy inserts through the actor call
    b = make_batch(2, start=12)
    assert by_call.insert(b, source_id=5)
    inserted.update({12 + r: (b, r) for r in range(2)})
    before = c.stats()
    b = make_batch(3, start=20)  # acknowledged in shared memory; the shard has not indexed it yet
    assert c.insert(b, source_id=6)
    inserted.update({20 + r: (b, r) for r in range(3)})
    pid = ray.get(c.shards[0].pid.remote())
    os.kill(pid, signal.SIGKILL)
    wait_shard_restarted(c, pid)
    after = c.stats()
    assert after["size_sequences"] == before["size_sequences"] + 3 == 17
    assert after["inserts"] == 17 and after["drops_corrupt"] == 0
    x = c.sample(300)  # the same mapping serves the restarted shard
    assert set(sample_ids(x)) == set(inserted)
    inserted[0][0].data["root_value"][0] = 5.0  # the write-back survived too
    _check_rows(x, inserted)
    w = {i: x.is_weight[r] for r, i in enumerate(sample_ids(x))}
    assert w[0] > w[11]  # priorities survived: rarer (lower priority) rows weigh more
    by_call.close()


def test_killed_collectors_uncommitted_rows_are_never_sampled(started, monkeypatch):
    """A collector that reserved slots and wrote its rows but died before committing them
    (simulated: its process stops right before the commit) leaves holes, never samples."""
    c = started(_cfg(), name="dead")
    assert c.insert(make_batch(4), source_id=0)
    collector = pickle.loads(pickle.dumps(c))

    class Killed(BaseException):
        pass

    def die(*args):
        raise Killed

    monkeypatch.setattr(replay_shm, "commit_rows", die)
    with pytest.raises(Killed):
        collector.insert(make_batch(3, start=50), source_id=1)
    monkeypatch.undo()
    assert c.insert(make_batch(2, start=4), source_id=2)
    st = c.stats()
    assert st["size_sequences"] == 6 and st["inserts"] == 6
    assert set(sample_ids(c.sample(400))) == set(range(6))


def test_write_backs_of_rewritten_rows_are_dropped_and_counted(started):
    c = started(_cfg(capacity_steps=16 * T, sampler="prioritized"), name="wb")
    assert c.insert(make_batch(16), source_id=0)
    s = c.sample(64)
    assert c.insert(make_batch(8, start=100), source_id=1)  # evicts the oldest (and reserves ahead)
    fields = {"root_value": np.full((64, T), 3.0, np.float32)}
    live = {int(i) for i in sample_ids(c.sample(300))}
    fresh = np.array([i in live for i in sample_ids(s)])
    applied = c.write_back(s.keys, s.stamps, fields)
    assert applied == fresh.sum() and 0 < applied < 64
    st = c.stats()
    assert st["drops_stale_writeback"] == 64 - applied
    assert c.update_priorities(s.keys, s.stamps, np.ones(64)) == applied
    assert c.stats()["drops_stale_priority"] == 64 - applied
    x = c.sample(300)
    written = set(sample_ids(s)[fresh])
    for row, i in enumerate(sample_ids(x)):
        assert np.all(x.data["root_value"][row] == (3.0 if i in written else 0.0))


@pytest.mark.parametrize("why", ["shm off", "other node"])
def test_actor_call_fallback(started, monkeypatch, why, tmp_path):
    if why == "other node":  # the client's process is not on the shards' node
        monkeypatch.setattr(replay_shm, "node_id", lambda: "elsewhere")
    c = started(_cfg(shards=2 if why == "shm off" else 1, shm=why == "other node", max_policy_lag=2),
                name=f"fb{why[0]}")
    assert bool(_segments(tmp_path, f"fb{why[0]}")) == (why == "other node")
    c.set_policy_version(5)
    b = make_batch(6)  # versions 0..5: 0, 1 and 2 fall behind max_policy_lag
    assert c.insert(b, source_id=0)
    assert c._shm is None
    x = c.sample(200)
    assert set(sample_ids(x)) == {3, 4, 5}
    _check_rows(x, {i: (b, i) for i in range(6)})
    assert c.write_back(x.keys[:1], x.stamps[:1], {"root_value": np.ones((1, T), np.float32)}) == 1
    st = c.stats()
    assert st["drops_policy_lag"] == 3 and st["size_sequences"] == 3
