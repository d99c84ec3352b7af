"""RecordLayout: fast encode / batch decode of the records of one schema (no new format).

For a fixed schema (field names, dtypes, shapes, T) `codec.encode_record` writes the same
bytes everywhere except the array payloads and the metadata tail. A layout precomputes
those fixed header bytes once, so

- `encode_rows(data, mask, meta)` is one `bytes.join` of headers and array buffers per row
  (no msgpack walk),
- `decode_many(raws)` checks each record's header bytes against the template and copies the
  payloads into the `[U, T, ...]` arrays, unpacking only the small metadata tail with
  msgpack. Small records are staged in one `[U, bytes]` buffer (one numpy call per record,
  headers compared and fields cut out for the whole batch at once); large ones are checked
  in place and each payload copied once.

The bytes are exactly those of `codec.encode_record` with the arrays in canonical order
(sorted field names, then `_mask`); the constructor checks that on a zero record. A record
that does not match the template byte for byte (other field order, an old writer, or
corruption) goes through the full checked decoder, so nothing is accepted that
`decode_checked` would refuse, and a crafted payload still can't run code.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Mapping, Sequence

import msgpack
import numpy as np

from wmdist.replay.codec import CodecError, check_dtype, decode_record, encode_record

MASK = "_mask"
SMALL_RECORD = 1 << 16  # bytes: below, records are staged in one buffer (fewer numpy calls)
_STR, _NUM = frozenset([str]), frozenset([int, float])
# one array: (name, dtype name, shape including the leading T)
Schema = tuple[tuple[str, str, tuple[int, ...]], ...]


def schema_of(fields: Mapping[str, object], seq_len: int) -> Schema:
    """Canonical schema of FieldSpec-like objects (`.shape`, `.dtype`), `_mask` last."""
    cols = [(k, check_dtype(np.dtype(s.dtype), k), (seq_len, *s.shape)) for k, s in sorted(fields.items())]
    return (*cols, (MASK, "bool", (seq_len,)))


@lru_cache(maxsize=64)
def layout_for(schema: Schema) -> "RecordLayout":
    return RecordLayout(schema)


class RecordLayout:
    def __init__(self, schema: Schema) -> None:
        self.schema = schema
        self.names = [n for n, _, _ in schema]
        self.dtypes = [np.dtype(d) for _, d, _ in schema]
        self.shapes = [s for _, _, s in schema]
        self.nbytes = [int(np.prod(s)) * dt.itemsize for s, dt in zip(self.shapes, self.dtypes)]
        pk = msgpack.Packer(use_bin_type=True)
        head = pk.pack_map_header(2) + msgpack.packb("a") + pk.pack_map_header(len(schema))
        self.headers: list[bytes] = []  # fixed bytes before each payload
        self.offsets: list[int] = []  # start of each payload in the record
        pos = 0
        for i, (name, dname, shape) in enumerate(schema):
            n = self.nbytes[i]
            arr = msgpack.packb({"d": dname, "s": list(shape), "b": bytes(n)}, use_bin_type=True)
            h = (head if i == 0 else b"") + msgpack.packb(name) + arr[:len(arr) - n]
            self.headers.append(h)
            pos += len(h)
            self.offsets.append(pos)
            pos += n
        self.end = pos  # end of the last payload; the tail "m" + meta map follows
        self.tail_key = msgpack.packb("m")
        # positions and values of every fixed byte before `end` (vectorised header check)
        self._head_pos = np.concatenate([np.arange(o - len(h), o) for h, o in zip(self.headers, self.offsets)])
        self._head_bytes = np.frombuffer(b"".join(self.headers), np.uint8)
        zeros = {n: np.zeros(s, dt) for n, s, dt in zip(self.names, self.shapes, self.dtypes)}
        mine = self.encode_rows({n: z[None] for n, z in zeros.items() if n != MASK}, zeros[MASK][None],
                                [{"steps": 0}])[0]
        if mine != encode_record(zeros, {"steps": 0}):
            raise AssertionError("record layout disagrees with codec.encode_record")  # a msgpack change

    # -- encode ---------------------------------------------------------------------------
    def encode_rows(self, data: Mapping[str, np.ndarray], mask: np.ndarray, meta: Sequence[dict]) -> list[bytes]:
        """One record per row of `data[name] [N, T, ...]` and `mask [N, T]`."""
        cols = [np.ascontiguousarray(data[n]) for n in self.names[:-1]] + [np.ascontiguousarray(mask)]
        for n, c, dt, shape in zip(self.names, cols, self.dtypes, self.shapes):
            if c.dtype != dt or c.shape[1:] != shape:
                raise ValueError(f"'{n}' is {c.dtype}{c.shape[1:]} per row, expected {dt}{shape}")
        out = []
        for r, m in enumerate(meta):
            parts: list = []
            for h, c in zip(self.headers, cols):
                parts += (h, c[r])
            parts += (self.tail_key, msgpack.packb(m, use_bin_type=True))
            out.append(b"".join(parts))
        return out

    # -- decode ---------------------------------------------------------------------------
    def _meta(self, raw: bytes) -> dict | None:
        """The metadata tail of a record with the template's length, None if it is not one."""
        tail = self.end + len(self.tail_key)
        if len(raw) <= tail or not raw.startswith(self.tail_key, self.end):
            return None
        try:  # (defaults: raw=False, strict_map_key=True, no ext hook)
            m = msgpack.unpackb(memoryview(raw)[tail:])
        except Exception:  # msgpack raises several types for bad input
            return None
        # names -> numbers (bool excluded), as `codec.decode_record` requires; set ops run in C
        ok = type(m) is dict and _STR.issuperset(map(type, m)) and _NUM.issuperset(map(type, m.values()))
        return m if ok else None

    def decode_many(self, raws: Sequence[bytes | None]) -> tuple[dict[str, np.ndarray], np.ndarray, list]:
        """U stored records -> (arrays `{name: [U, T, ...]}` incl. `_mask`, state [U] int8
        (0 ok, 1 missing (None), 2 corrupt), meta per row (None unless ok)). Rows that are
        not ok hold zeros."""
        U = len(raws)
        out = {n: np.zeros((U, *s), dt) for n, s, dt in zip(self.names, self.shapes, self.dtypes)}
        state = np.zeros(U, np.int8)
        metas: list = [None] * U
        if U == 0:
            return out, state, metas
        flat = [out[n].reshape(U, -1).view(np.uint8) for n in self.names]  # [U, nbytes] byte views
        fast = np.zeros(U, bool)
        for i, raw in enumerate(raws):
            if raw is None:
                state[i] = 1
            elif type(raw) is bytes:
                metas[i] = self._meta(raw)
                fast[i] = metas[i] is not None
        rows = np.flatnonzero(fast)
        if self.end <= SMALL_RECORD:  # copy each record once, check headers and cut fields column-wise
            buf = np.zeros((rows.size, self.end), np.uint8)  # [R, end]
            for j, i in enumerate(rows):
                buf[j] = np.frombuffer(raws[i], np.uint8, self.end)
            same = (buf[:, self._head_pos] == self._head_bytes).all(axis=1)
            for f, (o, n) in zip(flat, zip(self.offsets, self.nbytes)):
                f[rows] = buf[:, o:o + n]
            fast[rows[~same]] = False
        else:  # large payloads: check headers in place, copy each field once into its array
            for i in rows:
                raw = raws[i]
                if all(raw.startswith(h, o - len(h)) for h, o in zip(self.headers, self.offsets)):
                    for f, o, n in zip(flat, self.offsets, self.nbytes):
                        f[i] = np.frombuffer(raw, np.uint8, n, o)
                else:
                    fast[i] = False
        for i in np.flatnonzero(~fast & (state == 0)):  # not the template's bytes: the checked decoder
            metas[i] = None
            try:
                arrs, m = decode_record(raws[i])
                for n, dt, shape in zip(self.names, self.dtypes, self.shapes):
                    if n not in arrs or arrs[n].dtype != dt or arrs[n].shape != shape:
                        raise CodecError(f"'{n}' missing or not {dt}{shape}")
                for n in self.names:
                    out[n][i] = arrs[n]
                metas[i] = m
            except CodecError:
                state[i] = 2
        steps = out[MASK].sum(axis=1)
        for i in np.flatnonzero(state == 0):  # metadata must agree with the mask
            s = metas[i].get("steps")
            if type(s) is not int or s != steps[i]:
                state[i], metas[i] = 2, None
        bad = np.flatnonzero(state)
        if bad.size:
            for a in out.values():
                a[bad] = 0
        return out, state, metas
