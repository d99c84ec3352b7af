"""Client inserts without a transaction (records, then a small announcement): acknowledged
inserts survive SIGKILL of redis-server and the shard; records whose announcement never ran
(a crash in between) are deleted at the next load and never become visible, not even
half-written; and the load's sweep never deletes the records of an insert announced while
it runs (the announcement is refused instead, or the sweep reads again)."""
from __future__ import annotations

import numpy as np
import pytest
from replay_helpers import FIELDS, T, make_batch

from wmdist.replay import storage_redis
from wmdist.replay.redis_server import RedisServer
from wmdist.replay.shard import ReplayShard
from wmdist.replay.storage_redis import (_ANNOUNCE, RedisStorage, commit_records, encode_rows, new_keys,
                                         pending_entry, put_records)


def _shard(r, ns: str, capacity: int = 16) -> ReplayShard:
    return ReplayShard(FIELDS, T, capacity, "uniform", 1.0, RedisStorage(FIELDS, capacity, T, r, ns))


def _write(ns: str, batch) -> tuple[str, dict[str, bytes], bytes]:
    keys = new_keys(ns, len(batch))
    entry = pending_entry(keys, batch.version, batch.episode_id, batch.mask.sum(1))
    return ns, dict(zip(keys, encode_rows(batch, np.arange(len(batch))))), entry


def _ids(sh: ReplayShard) -> set[int]:
    return set(sh.sample(200)["data"]["obs"][:, 0, 0].astype(int).tolist())


@pytest.mark.parametrize("big", [False, True], ids=["mset", "one-set-each"])
def test_a_crash_between_records_and_announcement_leaves_nothing_visible(tmp_path, monkeypatch, big):
    if big:  # every insert takes the pixel path: one SET per record
        monkeypatch.setattr(storage_redis, "BIG_WRITE", 0)
    server = RedisServer(str(tmp_path), appendfsync="always").start()
    try:
        r, ns = server.client(), "wmdist:crash:s0"
        sh = _shard(r, ns)
        assert commit_records(r, [_write(ns, make_batch(3))]) == []  # acknowledged
        assert commit_records(r, [_write(ns, make_batch(2, start=3, steps=np.array([T, 2])))]) == []
        # a client died after sending its records, before the announcement: whole records and
        # one cut short in transit, none of them named by any pending entry
        lost = _write(ns, make_batch(2, start=10))[1]
        put_records(r, lost)
        cut = next(iter(lost.values()))
        r.set(f"{ns}:r:cut.0", cut[:len(cut) // 2])
        server.kill()  # SIGKILL redis-server; the shard process is gone too (a fresh one below)
        server.start()
        r = server.client()
        sh2 = _shard(r, ns)
        st = sh2.stats()
        assert st["size_sequences"] == 5 and st["size_steps"] == 4 * T + 2
        assert st["drops_unacked"] == 3 and st["drops_corrupt"] == 0
        assert not any(r.exists(k) for k in [*lost, f"{ns}:r:cut.0"])
        assert _ids(sh2) == {0, 1, 2, 3, 4}
        assert _shard(r, ns).stats()["drops_unacked"] == 0  # swept once, nothing left behind
        del sh
    finally:
        server.stop()


def test_an_announcement_is_refused_when_a_record_was_swept(redis_server, namespace):
    r = redis_server.client()
    ns, recs, entry = _write(namespace, make_batch(3))
    put_records(r, recs)
    keys = list(recs)
    r.delete(keys[1])  # swept by a restarting shard between this insert's SETs and its announcement
    assert r.eval(_ANNOUNCE, len(keys) + 1, *keys, f"{ns}:pending", entry) == 0
    assert r.llen(f"{ns}:pending") == 0 and not any(r.exists(k) for k in keys)  # nothing left half-written
    assert r.eval(_ANNOUNCE, 1, f"{ns}:pending", pending_entry([], [], [], [], 2)) == 1  # lag-only entry
    put_records(r, recs)
    assert r.eval(_ANNOUNCE, len(keys) + 1, *keys, f"{ns}:pending", entry) == 1 and r.llen(f"{ns}:pending") == 2


def test_the_sweep_reads_again_when_an_insert_is_announced_under_it(redis_server, namespace, monkeypatch):
    """A client's records are in redis, unannounced, when a shard restarts; its announcement
    lands between the sweep's read of the pending list and the DEL. The sweep must not delete
    them (WATCH aborts it; it reads again) and the shard then indexes them."""
    r = redis_server.client()
    sh = _shard(r, namespace)
    commit_records(r, [_write(namespace, make_batch(2))])  # announced, not indexed yet: pending is not empty
    ns, recs, entry = _write(namespace, make_batch(2, start=5))
    put_records(r, recs)  # in flight
    parse, calls = storage_redis._parse_entry, []

    def parse_then_announce(raw, prefix, seq_len):
        calls.append(1)
        if len(calls) == 1:  # the sweep's first read: the client's announcement arrives now
            other = redis_server.client()
            assert other.eval(_ANNOUNCE, len(recs) + 1, *recs, f"{ns}:pending", entry) == 1
        return parse(raw, prefix, seq_len)

    monkeypatch.setattr(storage_redis, "_parse_entry", parse_then_announce)
    sh2 = _shard(r, namespace)  # restart: load sweeps, then indexes what is pending
    monkeypatch.setattr(storage_redis, "_parse_entry", parse)
    assert len(calls) >= 3  # the sweep read the list twice
    st = sh2.stats()
    assert st["size_sequences"] == 4 and st["drops_unacked"] == 0 and st["drops_corrupt"] == 0
    assert all(r.exists(k) for k in recs) and _ids(sh2) == {0, 1, 5, 6}
    del sh
