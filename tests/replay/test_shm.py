"""Shared-memory replay without Ray: the segment, the shard's reservations and commits, the
seqlock read (deterministic interleavings), re-attaching after a crash, checkpoints."""
from __future__ import annotations

import numpy as np
import pytest
from replay_helpers import FIELDS, T, make_batch

from wmdist.algos.base import FieldSpec
from wmdist.replay import shard_shm
from wmdist.replay.shard import ReplayShard
from wmdist.replay.shard_shm import ShmShard
from wmdist.replay.shm import ShmSegment, segment_prefix, sweep
from wmdist.replay.shm_rows import ShmRows, commit_rows, read_rows, write_rows


@pytest.fixture
def shm_name(tmp_path):
    prefix = segment_prefix("test", str(tmp_path))
    yield prefix + "s0"
    sweep(prefix)


def _shard(name: str, capacity: int = 32, token: int = 1, sampler: str = "uniform") -> ShmShard:
    return ShmShard(FIELDS, T, capacity, ShmSegment.open(name, FIELDS, capacity, T, token), sampler, 1.0)


def _read(seg: ShmSegment, slots: np.ndarray, stamps: np.ndarray, on_copied=None):
    k = len(slots)
    out = {f: np.empty((k, T, *s.shape), s.dtype) for f, s in FIELDS.items()}
    mask = np.empty((k, T), bool)
    bad = read_rows(ShmRows([seg], list(FIELDS)), np.zeros(k, np.int64), slots, stamps, out, mask, on_copied)
    return out, mask, bad


def _client_insert(sh: ShmShard, batch) -> np.ndarray:
    """What a client does: reserve, write, commit in the segment (no shard call after reserve)."""
    r = sh.reserve(len(batch))
    assert len(r["slots"]) == len(batch)
    write_rows(sh.seg, r["slots"], batch)
    commit_rows(sh.seg, r["slots"], r["stamps"], batch.version, batch.episode_id, batch.mask.sum(1))
    return r["slots"]


def test_reads_return_exactly_what_was_written_by_either_path(shm_name):
    sh = _shard(shm_name)
    a = make_batch(4, steps=np.array([T, 3, 5, 1]))  # through the shard (actor-call path)
    sh.insert(a)
    b = make_batch(5, start=10, steps=np.array([2, T, T, 4, 7]))  # written by a "client"
    _client_insert(sh, b)
    d = sh.draw(400)
    data, mask, bad = _read(sh.seg, d["slots"], d["stamps"])
    assert bad.size == 0 and sh.stats()["size_sequences"] == 9
    ids = data["obs"][:, 0, 0].astype(int)
    assert set(ids) == {0, 1, 2, 3, 10, 11, 12, 13, 14}
    want = {int(i): (x, r) for x in (a, b) for r, i in enumerate(x.episode_id)}
    for row, i in enumerate(ids):
        x, r = want[i]
        assert np.array_equal(mask[row], x.mask[r])
        for f in FIELDS:
            assert np.array_equal(data[f][row], x.data[f][r]), f


def test_seqlock_rejects_rows_rewritten_during_the_copy(shm_name):
    """Between the copy and the re-check: a write-back, an eviction by the shard's own insert,
    and a client's reservation each make their row fail; the untouched rows pass."""
    sh = _shard(shm_name, capacity=8)
    sh.insert(make_batch(8))  # slots 0..7 hold sequences 0..7
    slots = np.arange(8)
    stamps = sh.stamp[slots].copy()

    def interleave() -> None:
        sh.write_back(np.array([1]), stamps[[1]], {"root_value": np.ones((1, T), np.float32)})
        sh.insert(make_batch(1, start=50))  # the ring evicts slot 0
        sh.reserve(2)  # slots 1 and 2 leave the index for a client's write

    data, _, bad = _read(sh.seg, slots, stamps, interleave)
    assert bad.tolist() == [0, 1, 2]
    assert data["obs"][3:, 0, 0].tolist() == [3, 4, 5, 6, 7]
    _, _, bad = _read(sh.seg, slots, stamps)  # read again afterwards: still not the drawn rows
    assert bad.tolist() == [0, 1, 2]
    _, _, bad = _read(sh.seg, np.array([0]), sh.stamp[[0]].copy())  # the new row, with its own stamp
    assert bad.size == 0


def test_restarted_shard_reattaches_everything_acknowledged(shm_name):
    sh = _shard(shm_name, sampler="prioritized")
    sh.insert(make_batch(6, steps=np.array([T, 2, 3, T, 5, 6])))
    s = {"slots": np.arange(6), "stamps": sh.stamp[:6].copy()}
    sh.update_priorities(s["slots"], s["stamps"], np.arange(6) + 1.0)
    sh.write_back(s["slots"][:1], s["stamps"][:1], {"root_value": np.full((1, T), 7.0, np.float32)})
    _client_insert(sh, make_batch(3, start=20))  # acknowledged, not indexed yet (no read since)
    dead = sh.reserve(2)  # a client that died before its commit
    write_rows(sh.seg, dead["slots"], make_batch(2, start=90))
    stamp, prio = sh.stamp.copy(), sh.priority.copy()
    # the process dies (nothing runs at exit); Ray starts the actor again with the same token
    again = _shard(shm_name, sampler="prioritized")
    assert not again.seg.fresh
    st = again.stats()
    assert st["size_sequences"] == 9 and st["inserts"] == 9 and again.count == 11
    live = stamp >= 0
    assert np.array_equal(again.stamp[live], stamp[live]) and np.allclose(again.priority[live], prio[live])
    d = again.draw(500)
    data, _, bad = _read(again.seg, d["slots"], d["stamps"])
    assert bad.size == 0 and set(data["obs"][:, 0, 0].astype(int)) == {0, 1, 2, 3, 4, 5, 20, 21, 22}
    wb, _, _ = _read(again.seg, s["slots"][:1], s["stamps"][:1])
    assert np.all(wb["root_value"] == 7.0)  # the write-back survived too
    assert again.tree.total == pytest.approx(21.0 + 3 * 6.0)  # priorities 1..6, new rows at max (6)
    # another service of the same run name: the stale segment is replaced, not attached
    other = _shard(shm_name, token=2)
    assert other.seg.fresh and other.stats()["size_sequences"] == 0


@pytest.mark.parametrize("path", ["drain", "insert"])
def test_inserts_counter_is_exact_when_the_shard_dies_while_indexing(shm_name, path):
    """Death between making rows live (stamps) and counting them: the restarted shard's
    counter is the count before plus the rows made live, neither short nor doubled."""
    sh = _shard(shm_name)
    sh.insert(make_batch(4))
    if path == "drain":
        _client_insert(sh, make_batch(3, start=20))  # acknowledged; the next read indexes it

    class Died(BaseException):
        pass

    def die(*args):  # the tree is set after the stamps, before the counter
        raise Died

    sh.tree.set = die
    with pytest.raises(Died):
        sh.drain() if path == "drain" else sh.insert(make_batch(3, start=20))
    assert sh.counters["inserts"] == 4 and int((sh.stamp >= 0).sum()) == 7  # live, not counted
    again = _shard(shm_name)
    st = again.stats()
    assert st["size_sequences"] == 7 and st["inserts"] == 7
    assert again.drain() == 0 and again.stats()["inserts"] == 7  # a drain's rows are not indexed twice
    again.insert(make_batch(1, start=40))
    assert again.stats()["inserts"] == 8


def test_a_row_torn_by_a_crash_is_dropped_on_reattach(shm_name):
    sh = _shard(shm_name)
    sh.insert(make_batch(3))
    sh.gen[1] += 1  # the shard died in the middle of rewriting slot 1 (generation left odd)
    again = _shard(shm_name)
    assert again.stats()["size_sequences"] == 2 and again.stats()["drops_corrupt"] == 1
    assert again.gen[1] % 2 == 0 and again.stamp[1] == -1


def test_uncommitted_reservations_are_holes_until_their_lease_lapses(shm_name, monkeypatch):
    sh = _shard(shm_name, capacity=8)
    sh.insert(make_batch(2))
    dead = sh.reserve(2)  # a collector reserved, wrote, and was killed before committing
    write_rows(sh.seg, dead["slots"], make_batch(2, start=70))
    sh.insert(make_batch(2, start=2))
    d = sh.draw(300)
    assert set(d["slots"].tolist()) == {0, 1, 4, 5} and sh.stats()["size_sequences"] == 4
    assert not set(dead["slots"].tolist()) & set(d["slots"].tolist())
    sh.insert(make_batch(4, start=4))  # the ring comes round to slots 6, 7, 0, 1: leased 2, 3 are skipped
    assert sh.stamp.tolist() == [8, 9, -1, -1, 4, 5, 6, 7]
    assert set(np.flatnonzero(sh.lease >= 0).tolist()) == {2, 3}
    monkeypatch.setattr(shard_shm, "LEASE_SECONDS", 0.0)  # the lease lapses: the slots are reused
    sh.insert(make_batch(2, start=10))
    assert sh.lease[2] == -1 and sh.stamp[2] >= 0
    commit_rows(sh.seg, dead["slots"], dead["stamps"], np.zeros(2, np.int64), np.zeros(2, np.int64),
                np.full(2, T))  # a late commit of the lapsed reservation is ignored
    assert sh.stats()["size_sequences"] == 8 and 70 not in sh.episode


def test_commit_records_out_of_range_are_refused_and_policy_lag_counted(shm_name):
    sh = _shard(shm_name)
    r = sh.reserve(2)
    commit_rows(sh.seg, r["slots"], r["stamps"], np.zeros(2, np.int64), np.zeros(2, np.int64), np.array([T, T + 1]))
    sh.count_lag(3)
    st = sh.stats()
    assert st["size_sequences"] == 1 and st["drops_corrupt"] == 1 and st["drops_policy_lag"] == 3


def test_checkpoints_are_the_plain_shards_npz(shm_name, tmp_path):
    sh = _shard(shm_name, capacity=8, sampler="prioritized")
    sh.insert(make_batch(11, steps=np.arange(11) % T + 1))  # wraps: 3 evicted
    s = sh.draw(5)
    sh.update_priorities(s["slots"], s["stamps"], np.arange(5) + 0.5)
    sh.save(str(tmp_path / "a.npz"))
    plain = ReplayShard(FIELDS, T, 8, "prioritized", 1.0)
    plain.restore(str(tmp_path / "a.npz"))
    for k, v in sh.storage.arrays().items():
        assert np.array_equal(v, plain.storage.arrays()[k]), k
    for k in ("stamp", "version", "episode", "steps", "priority", "born"):
        assert np.array_equal(getattr(sh, k), getattr(plain, k)), k
    assert sh.clock == plain.clock and sh.count == plain.count
    plain.save(str(tmp_path / "b.npz"))
    back = _shard(shm_name + "b", capacity=8, sampler="prioritized")
    try:
        back.restore(str(tmp_path / "b.npz"))
        assert np.array_equal(back.tree.tree, sh.tree.tree) and back.stats()["size_steps"] == sh.stats()["size_steps"]
        assert back.head == back.count % 8 and np.all(back.lease == -1)
    finally:
        back.close()


def test_memory_per_step_within_ten_percent_of_raw(shm_name):
    """The benchmark's vector fields (T = 64): ring arrays, mask and per-slot index."""
    fields = {"obs": FieldSpec((20,), "float32"), "action": FieldSpec((), "int64"),
              "reward": FieldSpec((), "float32"), "first": FieldSpec((), "bool"),
              "last": FieldSpec((), "bool"), "terminal": FieldSpec((), "bool")}
    seq_len, capacity = 64, 256
    sh = ShmShard(fields, seq_len, capacity, ShmSegment.open(shm_name, fields, capacity, seq_len, 1))
    raw = seq_len * sum(int(np.prod(s.shape)) * np.dtype(s.dtype).itemsize for s in fields.values())
    assert raw <= sh.stats()["bytes"] / capacity <= 1.1 * raw
    assert sh.seg.layout.size <= 1.1 * raw * capacity
