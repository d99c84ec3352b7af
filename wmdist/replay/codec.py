"""Array codec for stored records: msgpack maps with explicit dtype and shape, never pickle.

One array is encoded as the msgpack map `{"d": dtype-name, "s": [shape...], "b": raw bytes}`
(C order, little-endian as numpy writes it on x86/arm). A record is a map of such arrays
plus plain scalars. Decoding only builds numpy arrays from raw bytes with a dtype from an
allow-list, so a crafted payload can at worst fail to decode (`CodecError`); it can never
run code. Object, void and string dtypes are refused on both sides.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import msgpack
import numpy as np

# dtypes a record may hold (numeric and bool only: no object / void / str / datetime)
ALLOWED_DTYPES = frozenset(
    ["bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
     "float16", "float32", "float64"]
)
_DTYPES = {name: np.dtype(name) for name in ALLOWED_DTYPES}
_NAMES = {dt: name for name, dt in _DTYPES.items()}  # dtype.name is slow; look it up instead
_MAX_DIMS = 16


class CodecError(ValueError):
    """Bytes that are not a valid record (corrupt, truncated or crafted)."""


def check_dtype(dtype: np.dtype, what: str) -> str:
    """The dtype's name if storable, else one clear ValueError."""
    name = _NAMES.get(np.dtype(dtype))
    if name is None:
        raise ValueError(f"{what}: dtype {np.dtype(dtype).name} is not storable (numeric or bool only)")
    return name


def _pack_array(a: np.ndarray, what: str) -> dict[str, Any]:
    name = check_dtype(a.dtype, what)
    a = a if a.flags.c_contiguous else np.array(a, order="C")  # (ascontiguousarray would make 0-d 1-d)
    return {"d": name, "s": list(a.shape), "b": a.data if a.ndim else a.tobytes()}  # packed without a copy


def _unpack_array(m: Any, what: str) -> np.ndarray:
    if not isinstance(m, dict) or set(m) != {"d", "s", "b"}:
        raise CodecError(f"{what}: not an array map")
    dtype, shape, raw = m["d"], m["s"], m["b"]
    dt = _DTYPES.get(dtype) if isinstance(dtype, str) else None
    if dt is None:
        raise CodecError(f"{what}: dtype {dtype!r} refused")
    if (not isinstance(shape, list) or len(shape) > _MAX_DIMS
            or not all(isinstance(n, int) and n >= 0 for n in shape)):
        raise CodecError(f"{what}: bad shape {shape!r}")
    if not isinstance(raw, bytes):
        raise CodecError(f"{what}: payload is not bytes")
    if math.prod(shape) * dt.itemsize != len(raw):
        raise CodecError(f"{what}: {len(raw)} bytes do not make a {dtype}{tuple(shape)} array")
    return np.frombuffer(raw, dtype=dt).reshape(tuple(shape))


def encode_array(a: np.ndarray) -> bytes:
    """One array -> bytes."""
    return msgpack.packb(_pack_array(np.asarray(a), "array"), use_bin_type=True)


def decode_array(b: bytes) -> np.ndarray:
    """Bytes -> a read-only array view (copy it to write); CodecError if invalid."""
    return _unpack_array(_unpackb(b), "array")


def encode_record(arrays: Mapping[str, np.ndarray], meta: Mapping[str, int | float] | None = None) -> bytes:
    """A dict of named arrays plus scalar metadata -> bytes."""
    body = {"a": {k: _pack_array(np.asarray(v), k) for k, v in arrays.items()}, "m": dict(meta or {})}
    return msgpack.packb(body, use_bin_type=True)


def decode_record(b: bytes) -> tuple[dict[str, np.ndarray], dict[str, int | float]]:
    """Bytes -> (arrays, meta); CodecError if anything is off."""
    body = _unpackb(b)
    if not isinstance(body, dict) or set(body) != {"a", "m"} or not isinstance(body["a"], dict):
        raise CodecError("record: not a record map")
    meta = body["m"]
    if not isinstance(meta, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) for k, v in meta.items()
    ):
        raise CodecError("record: metadata must map names to numbers")
    arrays = {}
    for k, v in body["a"].items():
        if not isinstance(k, str):
            raise CodecError("record: array names must be strings")
        arrays[k] = _unpack_array(v, k)
    return arrays, meta


def _unpackb(b: bytes) -> Any:
    if not isinstance(b, (bytes, bytearray, memoryview)):
        raise CodecError(f"expected bytes, got {type(b).__name__}")
    try:
        # ext types are refused (no hook); strict_map_key keeps keys str/bytes only
        return msgpack.unpackb(b, raw=False, strict_map_key=True, use_list=True)
    except Exception as e:  # msgpack raises several types for bad input
        raise CodecError(f"undecodable bytes ({type(e).__name__})") from None
