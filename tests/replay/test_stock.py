"""A reader's stock of gathered samples (`wmdist/replay/stock.py`): sized by the reader's recent
calls and a byte budget, never served after a write of the reader or past the draws' age, and,
end to end on a real local Ray with real shards (shared memory and redis), every batch served
from it is an i.i.d. sample of the union of shards whose rows, keys and stamps belong
together; the rows the shared-memory gather copies from several shards against a plain loop."""
from __future__ import annotations

import numpy as np
import pytest
from replay_helpers import FIELDS, T, make_batch, sample_ids

from wmdist.replay.config import ReplayConfig
from wmdist.replay.rowcopy import RowSource
from wmdist.replay.stock import GatheredStock, Pace, batches_ahead


def test_pace_counts_calls_within_the_horizon():
    p = Pace(horizon=0.25, most=8)
    assert [p.tick(t) for t in (0.0, 0.01, 0.02)] == [1, 2, 3]
    assert p.tick(0.26) == 2  # 0.0 and 0.01 fell out of (0.01, 0.26]
    assert p.tick(5.0) == 1  # after a pause the reader counts as slow again
    assert max(p.tick(5.0 + i * 1e-4) for i in range(50)) == 8  # counted up to `most`


def test_batches_ahead_is_bounded_by_calls_bytes_and_most():
    assert batches_ahead(1, 100) == 1
    assert batches_ahead(20, 100, max_batches=32) == 20
    assert batches_ahead(40, 100, max_batches=32) == 32
    assert batches_ahead(40, 3 << 20, budget=8 << 20) == 2  # two 3 MB batches fit 8 MB
    assert batches_ahead(40, 12 << 20, budget=8 << 20) == 1  # a batch above the budget: one at a time


def _stock(n: int, batch: int, gen: int = 0, born: float = 0.0) -> GatheredStock:
    z = np.arange(n)
    return GatheredStock({"obs": z[:, None] * np.ones((1, 2))}, np.ones((n, 2), np.float32), np.zeros((n, 2)), z, z,
                         z, np.ones(n), n, float(n), batch, gen, born)


def test_stock_serves_until_a_write_an_age_or_a_size_change():
    st = _stock(12, 4, gen=3, born=10.0)
    assert st.serves(4, 3, 10.5, 1.0)
    assert not st.serves(4, 4, 10.5, 1.0)  # the reader wrote since the gather
    assert not st.serves(4, 3, 11.0, 1.0)  # as old as the draws may be
    assert not st.serves(5, 3, 10.5, 1.0)  # another batch size
    cuts = [st.take(4) for _ in range(3)]
    assert [c.start for c in cuts] == [0, 4, 8] and st.left() == 0 and not st.serves(4, 3, 10.5, 1.0)
    with pytest.raises(ValueError):
        st.take(1)


@pytest.mark.parametrize("shape,dtype", [((5, 3), np.float32), ((7,), bool), ((3, 3, 2), np.uint8), ((), np.int64)])
def test_row_copies_from_several_shards_match_fancy_indexing(shape, dtype):
    rng = np.random.default_rng(0)
    shards = [[(rng.random((50, *shape)) * 100).astype(dtype), rng.random((50, 4))] for _ in range(3)]
    src = RowSource(shards)
    shard_of, rows = rng.integers(0, 3, 12), rng.integers(0, 50, 12)
    for at in (None, rng.permutation(20)[:12]):
        n = 12 if at is None else 20
        dst, other = np.zeros((n, *shape), dtype), np.zeros((n, 4))
        ref, ref_other = dst.copy(), other.copy()
        places = np.arange(12) if at is None else at
        for i in range(12):  # the obviously-correct loop
            ref[places[i]] = shards[shard_of[i]][0][rows[i]]
            ref_other[places[i]] = shards[shard_of[i]][1][rows[i]]
        src.copy(shard_of, rows, [dst, other], at)
        assert np.array_equal(dst, ref) and np.array_equal(other, ref_other)
    dst, other = np.zeros((12, *shape), dtype), np.zeros((12, 4))
    for bad in ((np.array([3]), np.array([0])), (np.array([0]), np.array([50]))):  # shard 3, row 50
        with pytest.raises(IndexError):
            src.copy(*bad, [dst, other])
    with pytest.raises(IndexError):
        src.copy(np.array([0]), np.array([0]), [dst, other], at=np.array([12]))
    with pytest.raises(ValueError):
        src.copy(shard_of, rows, [dst[:, None], other])


def _cfg(backend: str, **kw) -> ReplayConfig:
    base = dict(backend=backend, shards=2, capacity_steps=64 * T, seq_len=T, min_size=0, shard_cpus=0.1)
    return ReplayConfig(**{**base, **kw})


@pytest.mark.parametrize("backend", ["memory", "redis"])
def test_back_to_back_samples_come_from_a_stock_of_iid_batches(started, backend):
    c = started(_cfg(backend))
    inserted = {}
    for src in range(4):
        b = make_batch(10, start=10 * src, steps=np.array([T, 1, 3, T, 5, T, 2, T, 7, T]))
        inserted.update({10 * src + r: (b, r) for r in range(10)})
        assert c.insert(b, source_id=src)
    sizes = [c.stats()[f"shard{s}_size_sequences"] for s in (0, 1)]
    assert min(sizes) > 0
    n, B = 400, 16
    key_of: dict[int, int] = {}
    shard0 = []
    for _ in range(n):
        s = c.sample(B)
        for row, i in enumerate(sample_ids(s)):  # rows, keys and stamps still belong together
            b, r = inserted[int(i)]
            assert np.array_equal(s.mask[row], b.mask[r].astype(np.float32))
            for f in FIELDS:
                assert np.array_equal(s.data[f][row], b.data[f][r]), f
            assert key_of.setdefault(int(i), int(s.keys[row])) == int(s.keys[row])
        assert s.age.shape == (B, T) and np.all(s.is_weight == 1.0)
        shard0.append(int(((s.keys >> 40) == 0).sum()))
    assert c.gathers <= n / 8  # back-to-back: one gather serves many samples
    # each batch is an i.i.d. sample of the union: its count from shard 0 is Binomial(B, p)
    p = sizes[0] / sum(sizes)
    counts = np.array(shard0)
    assert abs(counts.mean() - B * p) < 0.4
    assert 0.6 < counts.var() / (B * p * (1 - p)) < 1.5  # a batch from one shard only would give ~B/(p(1-p))x


@pytest.mark.parametrize("backend", ["memory", "redis"])
def test_a_write_of_the_reader_ends_its_stock(started, backend):
    c = started(_cfg(backend, sampler="prioritized", priority_alpha=1.0))
    assert c.insert(make_batch(20), source_id=0)
    for _ in range(40):
        c.sample(8)
    g = c.gathers
    assert g < 20
    s = c.sample(8)
    c.update_priorities(s.keys, s.stamps, np.full(8, 5.0))  # a learner step: the next sample must see it
    for _ in range(10):  # sample, write, sample, ...: a fresh gather of one batch each time
        s = c.sample(8)
        c.update_priorities(s.keys, s.stamps, np.full(8, 5.0))
    assert c.gathers - g >= 10
    # write-backs show at once: every row sampled after it carries the written value
    s = c.sample(8)
    c.write_back(s.keys, s.stamps, {"root_value": np.full((8, T), 7.0, np.float32)})
    for _ in range(20):
        got = c.sample(8)
        hit = np.isin(got.keys, s.keys)
        assert np.all(got.data["root_value"][hit] == 7.0)


def test_sample_ahead_1_gathers_every_sample_itself(started):
    c = started(_cfg("memory", sample_ahead=1))
    assert c.insert(make_batch(20), source_id=0)
    for _ in range(30):
        c.sample(8)
    assert c.gathers == 30
