"""RecordLayout (fast record encode / batch decode) against the reference codec: the same bytes,
the same arrays, and every record the checked decoder refuses is refused here too."""
from __future__ import annotations

import msgpack
import numpy as np
import pytest
from replay_helpers import FIELDS, T, make_batch

from wmdist.algos.base import FieldSpec
from wmdist.replay.codec import encode_record
from wmdist.replay.layout import SMALL_RECORD, layout_for, schema_of
from wmdist.replay.storage_redis import decode_checked, encode_rows

BIG = {"obs": FieldSpec((64, 64, 3), "uint8"), "reward": FieldSpec((), "float32")}  # > SMALL_RECORD


def _reference(batch, r: int) -> bytes:
    """encode_record of row r with the arrays in canonical order (sorted names, `_mask` last)."""
    arrs = {k: batch.data[k][r] for k in sorted(batch.data)}
    arrs["_mask"] = batch.mask[r]
    meta = {"version": int(batch.version[r]), "episode": int(batch.episode_id[r]), "steps": int(batch.mask[r].sum())}
    return encode_record(arrs, meta)


def _big_batch(n: int, seed: int = 0):
    from wmdist.replay.batch import SequenceBatch

    rng = np.random.default_rng(seed)
    steps = rng.integers(1, T + 1, n)
    mask = np.arange(T)[None] < steps[:, None]
    data = {"obs": rng.integers(0, 255, (n, T, 64, 64, 3), dtype=np.uint8),
            "reward": rng.random((n, T)).astype(np.float32)}
    return SequenceBatch(data, mask, rng.integers(0, 10**9, n), np.arange(n, dtype=np.int64))


@pytest.mark.parametrize("kind", ["small", "big"])
def test_encode_is_the_codec_and_decode_round_trips(kind):
    fields, batch = (FIELDS, make_batch(6, steps=np.array([T, 1, 3, T, 5, 2]))) if kind == "small" else (
        BIG, _big_batch(3))
    layout = layout_for(schema_of(fields, T))
    assert (layout.end <= SMALL_RECORD) == (kind == "small")  # both decode strategies are covered
    raws = encode_rows(batch, np.arange(len(batch)))
    assert raws == [_reference(batch, r) for r in range(len(batch))]  # byte for byte
    out, state, metas = layout.decode_many(raws + [None])
    assert state.tolist() == [0] * len(batch) + [1]
    for r in range(len(batch)):
        arrs, meta = decode_checked(raws[r], fields, T)  # the slow reference decoder
        assert metas[r] == meta
        for name in (*fields, "_mask"):
            assert out[name][r].dtype == arrs[name].dtype and np.array_equal(out[name][r], arrs[name]), name
    assert not out["_mask"][-1].any()  # the missing row is zeros


@pytest.mark.parametrize("kind", ["small", "big"])
def test_bad_records_are_corrupt_and_other_orders_still_decode(kind):
    fields, batch = (FIELDS, make_batch(2)) if kind == "small" else (BIG, _big_batch(2, seed=1))
    layout = layout_for(schema_of(fields, T))
    good = encode_rows(batch, np.arange(2))
    arrs, meta = decode_checked(good[0], fields, T)
    reordered = encode_record(dict(reversed(list(arrs.items()))), meta)  # valid, not the template
    name = sorted(fields)[0]
    h = layout.headers[0]
    bad = [
        b"\x93garbage",
        good[0][:-5],  # truncated tail
        good[0][:layout.offsets[1] - 3],  # truncated inside the arrays
        good[0].replace(b"float32", b"float64", 1),  # dtype no longer matches the bytes
        good[0][:len(h) - 1] + bytes([h[-1] ^ 1]) + good[0][len(h):],  # a header byte flipped
        encode_record(arrs, {**meta, "steps": meta["steps"] - 1}),  # metadata disagrees with the mask
        encode_record(arrs, {**meta, "steps": True}),  # bool is not a number here
        good[0][:layout.end] + msgpack.packb("m") + msgpack.packb({"steps": msgpack.ExtType(1, b"x")}),
        encode_record({k: v for k, v in arrs.items() if k != name}, meta),  # a field missing
    ]
    out, state, metas = layout.decode_many([reordered, *bad, good[1]])
    assert state.tolist() == [0] + [2] * len(bad) + [0]
    assert all(m is None for m in metas[1:-1])
    for f in (*fields, "_mask"):
        assert np.array_equal(out[f][0], arrs[f]) and not out[f][1:-1].any()
    assert np.array_equal(out[name][-1], decode_checked(good[1], fields, T)[0][name])


def test_encode_refuses_a_wrong_schema():
    layout = layout_for(schema_of(FIELDS, T))
    b = make_batch(1)
    with pytest.raises(ValueError, match="'obs'"):
        layout.encode_rows({**b.data, "obs": b.data["obs"].astype(np.float64)}, b.mask, [{"steps": T}])


@pytest.mark.parametrize("kind", ["small", "big"])
def test_a_batch_mixing_good_and_bad_records_decodes_each_row_like_the_reference(kind):
    """The batch decode (one pattern match, one tail pass and one cut for the batch) against
    the checked decoder row by row, with bad, missing and repeated records among good ones."""
    fields, batch = (FIELDS, make_batch(8, steps=np.array([T, 1, 3, T, 5, 2, 7, 4]))) if kind == "small" else (
        BIG, _big_batch(4, seed=2))
    layout = layout_for(schema_of(fields, T))
    good = encode_rows(batch, np.arange(len(batch)))
    arrs, meta = decode_checked(good[0], fields, T)
    bad = [
        good[1] + b"\x00",  # a byte after the metadata
        good[1][:len(good[1]) - 1],  # the metadata cut short
        good[2][:layout.end] + msgpack.packb("m") + msgpack.packb([1, 2]),  # metadata not a map
        encode_record(arrs, {**meta, "steps": float(meta["steps"])}),  # steps not an int
        bytearray(good[3])[:-1] + b"",  # not bytes, and cut short
    ]
    rows = [good[0], bad[0], None, good[1], bad[1], good[0], bad[2], bytearray(good[2]), bad[3], bad[4], *good[2:]]
    out, state, metas = layout.decode_many(rows)
    for r, raw in enumerate(rows):
        try:
            want, want_meta = decode_checked(bytes(raw), fields, T) if raw is not None else (None, None)
        except Exception:  # noqa: BLE001 - the reference refuses it: so must the batch decode
            want, want_meta = None, None
        assert state[r] == (1 if raw is None else 0 if want is not None else 2), r
        assert metas[r] == want_meta, r
        for f in (*fields, "_mask"):
            assert np.array_equal(out[f][r], want[f] if want is not None else np.zeros_like(out[f][r])), (r, f)
    assert (state == 0).sum() == len(good) + 2  # each good record, good[0] twice and the bytearray copy


@pytest.mark.parametrize("kind", ["small", "big"])
def test_all_template_records_with_one_inconsistent_row(kind):
    """Every record matches the template (the whole-batch cut) but one's metadata disagrees
    with its mask: that row alone is refused and zeroed."""
    fields, batch = (FIELDS, make_batch(5)) if kind == "small" else (BIG, _big_batch(3, seed=3))
    layout = layout_for(schema_of(fields, T))
    raws = encode_rows(batch, np.arange(len(batch)))
    arrs, meta = decode_checked(raws[1], fields, T)
    raws[1] = encode_record(arrs, {**meta, "steps": meta["steps"] % T + 1})
    out, state, metas = layout.decode_many(raws)
    assert state.tolist() == [0, 2] + [0] * (len(raws) - 2) and metas[1] is None
    assert not any(out[f][1].any() for f in out)
    assert np.array_equal(out["_mask"][0], batch.mask[0]) and np.array_equal(out["_mask"][2], batch.mask[2])
