"""Codec: exact round trips, object dtypes refused, crafted or corrupt bytes can't run code."""
from __future__ import annotations

import os
import pickle

import msgpack
import numpy as np
import pytest

from wmdist.replay.codec import ALLOWED_DTYPES, CodecError, decode_array, decode_record, encode_array, encode_record


@pytest.mark.parametrize("dtype", sorted(ALLOWED_DTYPES))
def test_round_trip_every_dtype(dtype):
    a = (np.arange(24) % 7).astype(dtype).reshape(2, 3, 4)
    b = decode_array(encode_array(a))
    assert b.dtype == a.dtype and b.shape == a.shape and np.array_equal(a, b)


def test_record_round_trip_and_non_contiguous():
    a = np.arange(20, dtype=np.float32).reshape(4, 5)[:, ::2]  # non-contiguous view
    arrs, meta = decode_record(encode_record({"x": a, "s": np.float64(2.5)}, {"stamp": 7, "p": 0.5}))
    assert np.array_equal(arrs["x"], a) and arrs["s"].shape == () and meta == {"stamp": 7, "p": 0.5}


@pytest.mark.parametrize("bad", [np.array([object(), 1], dtype=object), np.array(["ab"]), np.zeros(2, "V4")])
def test_unstorable_dtypes_refused(bad):
    with pytest.raises(ValueError, match="not storable"):
        encode_array(bad)


def test_crafted_payloads_fail_cleanly(tmp_path):
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    payloads = [
        pickle.dumps(Evil()),  # a pickle bomb: must not be unpickled
        msgpack.packb({"d": "object", "s": [1], "b": b"12345678"}),  # object dtype by name
        msgpack.packb({"d": "float32", "s": [3], "b": b"\0" * 8}),  # length != shape * itemsize
        msgpack.packb({"d": "float32", "s": [-1], "b": b""}),
        msgpack.packb(msgpack.ExtType(1, pickle.dumps(Evil()))),  # ext type carrying a pickle
        encode_array(np.arange(4))[:-3],  # truncated
        b"",
        b"\xc1\xc1\xc1",  # msgpack never-used byte
    ]
    for p in payloads:
        with pytest.raises(CodecError):
            decode_array(p)
        with pytest.raises(CodecError):
            decode_record(p)
    assert not marker.exists()
