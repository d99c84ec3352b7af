"""Redis storage: each sequence is one msgpack record in redis-server; the shard keeps the index.

Keys are namespaced by run and shard (`wmdist:<run>:s<shard>:...`):

- `...:q:<slot>`  string: `codec.encode_record` of the sequence's arrays (`[T, ...]` per field
  plus `_mask`) and its metadata (stamp, version, episode, steps);
- `...:prio`      hash slot -> priority (raw, before alpha);
- `...:meta`      hash: `count` (sequences ever written; the next slot is count % capacity),
  `capacity`, `seq_len` (a restart with another layout is refused).

An insert is one MULTI/EXEC (MSET + HSET), so it is all-or-nothing and, under
`appendfsync always`, fsynced before it is acknowledged. A sample is one MGET of the
distinct slots drawn. A write-back reads, patches and rewrites whole records (the shard is
the only writer of its namespace and holds its lock). After a restart `load()` scans the
namespace and returns what the shard needs to rebuild its index and priorities; records
that fail to decode are skipped and counted.
"""
from __future__ import annotations

import math

import numpy as np
import redis

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.codec import CodecError, decode_record, encode_record

_META = ("stamp", "version", "episode", "steps")


def connect(url: str, password_file: str = "") -> redis.Redis:
    """A redis client for `url`, with the password read from `password_file` if given."""
    if not url.startswith(("redis://", "rediss://", "unix://")):
        raise ValueError(f"replay.redis_url must start with redis://, rediss:// or unix://, got {url!r}")
    kw = {}
    if password_file:
        with open(password_file, encoding="utf-8") as f:
            kw["password"] = f.read().strip()
    return redis.Redis.from_url(url, socket_timeout=60, socket_connect_timeout=10, health_check_interval=30, **kw)


class RedisStorage:
    durable = True

    def __init__(self, fields: dict[str, FieldSpec], capacity: int, seq_len: int, client: redis.Redis,
                 namespace: str) -> None:
        self.fields, self.capacity, self.T = dict(fields), capacity, seq_len
        self.r = client
        self.ns = namespace
        self._names = list(fields) + ["_mask"]
        meta = {k.decode(): v.decode() for k, v in self.r.hgetall(f"{self.ns}:meta").items()}
        if meta:
            if int(meta.get("capacity", capacity)) != capacity or int(meta.get("seq_len", seq_len)) != seq_len:
                raise ValueError(
                    f"redis namespace {self.ns} holds capacity={meta.get('capacity')} seq_len={meta.get('seq_len')}, "
                    f"this shard has capacity={capacity} seq_len={seq_len}")
        else:
            self.r.hset(f"{self.ns}:meta", mapping={"count": 0, "capacity": capacity, "seq_len": seq_len})

    def _key(self, slot: int) -> str:
        return f"{self.ns}:q:{int(slot)}"

    @property
    def nbytes(self) -> int:
        return 0  # the bytes live in redis-server

    def _encode(self, arrays: dict[str, np.ndarray], mask: np.ndarray, meta: dict[str, int]) -> bytes:
        return encode_record({**arrays, "_mask": mask}, meta)

    def _decode(self, raw: bytes | None) -> tuple[dict[str, np.ndarray], dict]:
        """One stored record -> (arrays incl. `_mask`, meta); CodecError if anything is off."""
        if raw is None:
            raise CodecError("record is missing")
        arrs, meta = decode_record(raw)
        for name in self._names:
            if name not in arrs:
                raise CodecError(f"record lacks '{name}'")
            spec = self.fields.get(name, FieldSpec((), "bool"))
            a, want = arrs[name], (self.T, *spec.shape)
            if a.dtype != np.dtype(spec.dtype) or a.shape != want:
                raise CodecError(f"'{name}' is {a.dtype}{a.shape}, expected {spec.dtype}{want}")
        if not all(isinstance(meta.get(k), int) for k in _META) or int(arrs["_mask"].sum()) != meta["steps"]:
            raise CodecError("record metadata is inconsistent")
        return arrs, meta

    def write(self, slots: np.ndarray, batch: SequenceBatch, meta: dict[str, np.ndarray]) -> None:
        recs, prio = {}, {}
        for row, slot in enumerate(slots):
            recs[self._key(slot)] = self._encode({k: batch.data[k][row] for k in self.fields}, batch.mask[row],
                                                 {k: int(meta[k][row]) for k in _META})
            prio[int(slot)] = repr(float(meta["priority"][row]))
        p = self.r.pipeline(transaction=True)
        p.mset(recs)
        p.hset(f"{self.ns}:prio", mapping=prio)
        p.hset(f"{self.ns}:meta", "count", int(meta["stamp"][-1]) + 1)
        p.execute()

    def read(self, slots: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """-> (fields [B, T, ...], mask [B, T] bool, indices of rows that failed to decode)"""
        uniq, inv = np.unique(np.asarray(slots, np.int64), return_inverse=True)  # fetch each slot once
        raws = self.r.mget([self._key(s) for s in uniq]) if uniq.size else []
        U = uniq.size
        out = {k: np.empty((U, self.T, *s.shape), dtype=s.dtype) for k, s in self.fields.items()}
        mask = np.zeros((U, self.T), dtype=bool)
        bad_u = np.zeros(U, dtype=bool)
        for i, raw in enumerate(raws):
            try:
                arrs, _ = self._decode(raw)
            except CodecError:
                bad_u[i] = True
                continue
            for k in self.fields:
                out[k][i] = arrs[k]
            mask[i] = arrs["_mask"]
        if U == len(slots) and np.array_equal(uniq, slots):
            return out, mask, np.flatnonzero(bad_u)
        return {k: v[inv] for k, v in out.items()}, mask[inv], np.flatnonzero(bad_u[inv])

    def write_fields(self, slots: np.ndarray, fields: dict[str, np.ndarray]) -> None:
        keys = [self._key(s) for s in slots]
        recs = {}
        for row, (key, raw) in enumerate(zip(keys, self.r.mget(keys))):
            try:
                arrs, meta = self._decode(raw)
            except CodecError:
                continue  # corrupt: left for load/sample to count
            patched = {k: (fields[k][row] if k in fields else arrs[k]) for k in self.fields}
            recs[key] = self._encode(patched, arrs["_mask"], meta)
        if recs:
            self.r.mset(recs)

    def write_priorities(self, slots: np.ndarray, priorities: np.ndarray) -> None:
        if len(slots):
            self.r.hset(f"{self.ns}:prio", mapping={int(s): repr(float(p)) for s, p in zip(slots, priorities)})

    def load(self, chunk: int = 16) -> tuple[dict[str, np.ndarray], int, int]:
        """Scan the namespace -> (index arrays [capacity] incl. priority, count, corrupt records)."""
        C = self.capacity
        idx = {"stamp": np.full(C, -1, np.int64), "version": np.zeros(C, np.int64),
               "episode": np.zeros(C, np.int64), "steps": np.zeros(C, np.int64),
               "priority": np.zeros(C, np.float64)}
        prefix = f"{self.ns}:q:"
        slots = []
        for key in self.r.scan_iter(match=prefix + "*", count=1000):
            tail = key.decode()[len(prefix):]
            if tail.isdigit() and int(tail) < C:
                slots.append(int(tail))
        corrupt = 0
        for start in range(0, len(slots), chunk):
            part = slots[start:start + chunk]
            for s, raw in zip(part, self.r.mget([self._key(x) for x in part])):
                try:
                    _, meta = self._decode(raw)
                except CodecError:
                    corrupt += 1
                    continue
                for k in _META:
                    idx[k][s] = meta[k]
        for s, v in self.r.hgetall(f"{self.ns}:prio").items():
            try:
                s, v = int(s), float(v)
            except ValueError:
                continue
            if 0 <= s < C and idx["stamp"][s] >= 0 and math.isfinite(v) and v >= 0:
                idx["priority"][s] = v
        count = int(self.r.hget(f"{self.ns}:meta", "count") or 0)
        count = max(count, int(idx["stamp"].max()) + 1)
        return idx, count, corrupt

    def clear(self) -> None:
        """Delete this shard's namespace (tests and fresh runs)."""
        keys = list(self.r.scan_iter(match=f"{self.ns}:*", count=1000))
        for i in range(0, len(keys), 1000):
            self.r.delete(*keys[i:i + 1000])

    def close(self) -> None:
        self.r.close()
