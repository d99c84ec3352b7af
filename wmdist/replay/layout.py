"""RecordLayout: fast encode / batch decode of the records of one schema (no new format).

For a fixed schema (field names, dtypes, shapes, T) `codec.encode_record` writes the same
bytes everywhere except the array payloads and the metadata tail. A layout precomputes
those fixed header bytes once, so

- `encode_rows(data, mask, meta)` is one `bytes.join` of headers and array buffers per row
  (no msgpack walk),
- `decode_many(raws)` matches each record against the template (one compiled pattern: the
  fixed bytes, payload sizes and the tail key, checked in C), unpacks the small metadata
  tails of the batch in one streaming msgpack pass, and copies the payloads into `[U, T, ...]`
  arrays: small records are joined into one buffer and each field is cut for the whole batch
  with one strided gather; large ones have each payload copied once from the record.

The bytes are exactly those of `codec.encode_record` with the arrays in canonical order
(sorted field names, then `_mask`); the constructor checks that on a zero record. A record
that does not match the template byte for byte (other field order, an old writer, or
corruption) goes through the full checked decoder, so nothing is accepted that
`decode_checked` would refuse, and a crafted payload still can't run code.
"""
from __future__ import annotations

import re
from functools import lru_cache
from itertools import accumulate, chain
from typing import Mapping, Sequence

import msgpack
import numpy as np

from wmdist.replay.codec import CodecError, check_dtype, decode_record, encode_record

MASK = "_mask"
SMALL_RECORD = 1 << 16  # bytes: below, records are staged in one buffer (fewer numpy calls)
_DICT, _STR, _NUM, _INT = frozenset([dict]), frozenset([str]), frozenset([int, float]), frozenset([int])
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
        # the template as one pattern: fixed bytes, then exactly `nbytes` of any payload, ..., then
        # the tail key (a record matches iff its bytes up to the metadata are the template's)
        self._template = re.compile(b"".join(re.escape(h) + b".{%d}" % n for h, n in zip(self.headers, self.nbytes))
                                    + re.escape(self.tail_key), re.DOTALL)
        self._width = max(self.nbytes)  # widest field: the window of the batch cut
        self._pad = bytes(self._width) if pos <= SMALL_RECORD else b""
        zeros = {n: np.zeros(s, dt) for n, s, dt in zip(self.names, self.shapes, self.dtypes)}
        mine = self.encode_rows({n: z[None] for n, z in zeros.items() if n != MASK}, zeros[MASK][None],
                                [{"steps": 0}])[0]
        if mine != encode_record(zeros, {"steps": 0}):
            raise AssertionError("record layout disagrees with codec.encode_record")  # a msgpack change

    # -- encode ---------------------------------------------------------------------------
    def encode_rows(self, data: Mapping[str, np.ndarray], mask: np.ndarray, meta: Sequence[dict],
                    rows: Sequence[int] | None = None) -> list[bytes]:
        """One record per row of `data[name] [N, T, ...]` and `mask [N, T]` (those in `rows`,
        in that order, if given; `meta` has one entry per record). Each payload is copied
        once, straight from the caller's arrays into the record."""
        cols = [np.ascontiguousarray(data[n]) for n in self.names[:-1]] + [np.ascontiguousarray(mask)]
        for n, c, dt, shape in zip(self.names, cols, self.dtypes, self.shapes):
            if c.dtype != dt or c.shape[1:] != shape:
                raise ValueError(f"'{n}' is {c.dtype}{c.shape[1:]} per row, expected {dt}{shape}")
        flat = [memoryview(c.reshape(-1).view(np.uint8)) for c in cols]  # [N * nbytes] each
        fixed = list(zip(self.headers, flat, self.nbytes))
        out = []
        for r, m in zip(range(len(meta)) if rows is None else rows, meta):
            parts: list = []
            for h, f, n in fixed:
                parts += (h, f[r * n:(r + 1) * n])
            parts += (self.tail_key, msgpack.packb(m, use_bin_type=True))
            out.append(b"".join(parts))
        return out

    # -- decode ---------------------------------------------------------------------------
    def _meta(self, raw: bytes) -> dict | None:
        """The metadata tail of one record with the template's length, None if it is not one."""
        tail = self.end + len(self.tail_key)
        if len(raw) <= tail or not raw.startswith(self.tail_key, self.end):
            return None
        try:  # (defaults: raw=False, strict_map_key=True, no ext hook)
            m = msgpack.unpackb(memoryview(raw)[tail:])
        except Exception:  # msgpack raises several types for bad input
            return None
        return m if _meta_ok([m]) else None

    def _metas(self, raws: list[bytes]) -> list[dict | None]:
        """The metadata tails of records whose fixed bytes matched (tail key included), checked
        together; record by record only if one of them is off."""
        tail, unpack = self.end + len(self.tail_key), msgpack.unpackb  # (raw=False, strict_map_key)
        try:
            ms = [unpack(r[tail:]) for r in raws]
        except Exception:  # msgpack raises several types for bad input
            ms = []
        return ms if len(ms) == len(raws) and _meta_ok(ms) else [self._meta(r) for r in raws]

    def decode_many(self, raws: Sequence[bytes | None]) -> tuple[dict[str, np.ndarray], np.ndarray, list]:
        """U stored records -> (arrays `{name: [U, T, ...]}` incl. `_mask`, state [U] int8
        (0 ok, 1 missing (None), 2 corrupt), meta per row (None unless ok)). Rows that are
        not ok hold zeros. Records of the template's bytes are checked and cut for the whole
        batch; anything else goes through the full checked decoder."""
        U = len(raws)
        match = self._template.match  # C: every fixed byte and the payload sizes in one pass
        fast = [i for i, r in enumerate(raws) if type(r) is bytes and match(r)]
        metas: list = [None] * U
        if fast:
            ms = self._metas([raws[i] for i in fast])
            if any(m is None for m in ms):  # a bad tail: the checked decoder has the last word
                fast, ms = [i for i, m in zip(fast, ms) if m is not None], [m for m in ms if m is not None]
            for i, m in zip(fast, ms):
                metas[i] = m
        cut = self._cut_small if self.end <= SMALL_RECORD else self._cut_large
        out = cut([raws[i] for i in fast] if len(fast) < U else raws, fast, U)
        state = np.zeros(U, np.int8)
        if len(fast) < U:
            for i in sorted(set(range(U)) - set(fast)):
                if raws[i] is None:
                    state[i] = 1
                    continue
                try:  # not the template's bytes: the checked decoder
                    arrs, m = self.decode_one(raws[i])
                    for n in self.names:
                        out[n][i] = arrs[n]
                    metas[i] = m
                except CodecError:
                    state[i] = 2
        steps = [m.get("steps") if m is not None else None for m in metas]  # must agree with the mask
        real = out[MASK].sum(axis=1).tolist()  # (rows not ok hold garbage until zeroed below)
        if len(fast) < U or steps != real or not _INT.issuperset(map(type, steps)):
            for i in np.flatnonzero(state == 0):
                if type(steps[i]) is not int or steps[i] != real[i]:
                    state[i], metas[i] = 2, None
        bad = np.flatnonzero(state)
        if bad.size:
            for a in out.values():
                a[bad] = 0
        return out, state, metas

    def decode_one(self, raw: bytes) -> tuple[dict[str, np.ndarray], dict]:
        """One stored record through the full checked decoder -> (arrays incl. `_mask`, meta);
        CodecError unless every field is there with its dtype and shape and the meta's steps
        agree with the mask."""
        arrs, meta = decode_record(raw)
        for n, dt, shape in zip(self.names, self.dtypes, self.shapes):
            if n not in arrs:
                raise CodecError(f"record lacks '{n}'")
            if arrs[n].dtype != dt or arrs[n].shape != shape:
                raise CodecError(f"'{n}' is {arrs[n].dtype}{arrs[n].shape}, expected {dt}{shape}")
        if type(meta.get("steps")) not in _INT or int(arrs[MASK].sum()) != meta["steps"]:
            raise CodecError("record metadata is inconsistent")
        return arrs, meta

    def _cut_small(self, raws: list[bytes], rows: list[int], U: int) -> dict[str, np.ndarray]:
        """Small records (`raws`, of the template, for `rows`): joined into one buffer, then
        each field cut for the whole batch with one strided gather -> arrays [U, ...]."""
        if not raws:
            return self._empty(U)
        starts = np.array([0, *accumulate(map(len, raws[:-1]))], np.int64)  # [R]
        joined = b"".join([*raws, self._pad])  # pad: every window below stays inside the buffer
        # windows of `width` bytes starting at every byte (a view, nothing copied)
        win = np.ndarray((len(joined) - self._width + 1, self._width), np.uint8, joined, 0, (1, 1))
        cols = zip(self.names, self.dtypes, self.shapes, self.offsets, self.nbytes)
        if len(rows) == U:  # every row (the usual case): one copy per field, straight out
            return {name: win[starts + o, :n].view(dt).reshape(U, *shape) for name, dt, shape, o, n in cols}
        out = self._empty(U)
        for name, _, _, o, n in cols:
            out[name].reshape(U, -1).view(np.uint8)[rows] = win[starts + o, :n]
        return out

    def _cut_large(self, raws: list[bytes], rows: list[int], U: int) -> dict[str, np.ndarray]:
        """Large records: each field of each record copied once (no staging copy)."""
        out = self._empty(U)
        flat = [out[n].reshape(U, -1).view(np.uint8) for n in self.names]  # [U, nbytes] byte views
        for i, raw in zip(rows, raws):
            for f, o, n in zip(flat, self.offsets, self.nbytes):
                f[i] = np.frombuffer(raw, np.uint8, n, o)
        return out

    def _empty(self, U: int) -> dict[str, np.ndarray]:
        """Uninitialised [U, ...] arrays (the caller fills or zeroes every row): no memset of
        megabytes per call, the same allocation work as a plain copy."""
        return {n: np.empty((U, *s), dt) for n, s, dt in zip(self.names, self.shapes, self.dtypes)}


def _meta_ok(ms: list) -> bool:
    """Every tail maps names to numbers (bool excluded), as `codec.decode_record` requires;
    the set operations run in C."""
    return (_DICT.issuperset(map(type, ms)) and _STR.issuperset(map(type, chain.from_iterable(ms)))
            and _NUM.issuperset(map(type, chain.from_iterable(map(dict.values, ms)))))
