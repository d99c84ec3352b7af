"""Redis storage: sequence records live in redis-server; the shard keeps the index.

Keys are namespaced by run and shard (`wmdist:<run>:s<shard>:...`):

- `...:r:<token>` string: `codec.encode_record` of one sequence (`[T, ...]` per field plus
  `_mask`, and metadata version / episode / steps). Tokens are unique, so a key never
  changes meaning: a reader holding an old key finds the old record or nothing.
- `...:idx`  hash slot -> msgpack [key, stamp, version, episode, steps]: the shard's index;
- `...:prio` hash slot -> priority (raw, before alpha);
- `...:meta` hash: `count` (sequences ever indexed; the next slot is count % capacity),
  `capacity`, `seq_len` (a restart with another layout is refused).

Data path: record bytes can be written and read by any process (`put_records`,
`fetch_records`: one pipeline of SETs / one MGET), so collectors and the learner move bytes
to and from redis directly while the shard actor only indexes keys (`register`). The
shard's own `write` (used in-process) is records + register in one MULTI/EXEC.

Durability: `register` is one MULTI/EXEC (index, priorities, count, and DEL of the records
it evicts), issued after the records were written; under `appendfsync always` both are
fsynced before the insert is acknowledged. `load()` rebuilds the index and priorities
after a restart, skips and counts records that fail to decode, and deletes records no
index entry names (written by an insert that was never acknowledged).
"""
from __future__ import annotations

import math
import uuid

import msgpack
import numpy as np
import redis

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.codec import CodecError, decode_record, encode_record


def connect(url: str, password_file: str = "") -> redis.Redis:
    """A redis client for `url`, with the password read from `password_file` if given."""
    if not url.startswith(("redis://", "rediss://", "unix://")):
        raise ValueError(f"replay.redis_url must start with redis://, rediss:// or unix://, got {url!r}")
    kw = {}
    if password_file:
        with open(password_file, encoding="utf-8") as f:
            kw["password"] = f.read().strip()
    return redis.Redis.from_url(url, socket_timeout=60, socket_connect_timeout=10, health_check_interval=30, **kw)


class RecordsMissing(RuntimeError):
    """`register` found some of the records it should index missing."""


# -- records (any process) ------------------------------------------------------------------
def encode_rows(batch: SequenceBatch, rows: np.ndarray) -> list[bytes]:
    """One record per selected window of the batch."""
    steps = batch.mask.sum(axis=1)
    return [encode_record({**{k: v[r] for k, v in batch.data.items()}, "_mask": batch.mask[r]},
                          {"version": int(batch.version[r]), "episode": int(batch.episode_id[r]),
                           "steps": int(steps[r])}) for r in rows]


def new_keys(namespace: str, n: int) -> list[str]:
    """n fresh, never-reused record keys in a shard's namespace."""
    tok = uuid.uuid4().hex
    return [f"{namespace}:r:{tok}.{i}" for i in range(n)]


def put_records(r: redis.Redis, records: dict[str, bytes]) -> None:
    """Write records (not yet visible: the shard's `register` indexes them)."""
    if records:  # pipelined SETs: one round trip, and redis parses one record per command
        p = r.pipeline(transaction=False)
        for k, v in records.items():
            p.set(k, v)
        p.execute()


def decode_checked(raw: bytes, fields: dict[str, FieldSpec], seq_len: int) -> tuple[dict[str, np.ndarray], dict]:
    """One stored record -> (arrays incl. `_mask`, meta); CodecError unless it fits the fields."""
    arrs, meta = decode_record(raw)
    for name in (*fields, "_mask"):
        if name not in arrs:
            raise CodecError(f"record lacks '{name}'")
        spec = fields.get(name, FieldSpec((), "bool"))
        a, want = arrs[name], (seq_len, *spec.shape)
        if a.dtype != np.dtype(spec.dtype) or a.shape != want:
            raise CodecError(f"'{name}' is {a.dtype}{a.shape}, expected {spec.dtype}{want}")
    if not isinstance(meta.get("steps"), int) or int(arrs["_mask"].sum()) != meta["steps"]:
        raise CodecError("record metadata is inconsistent")
    return arrs, meta


def fetch_records(r: redis.Redis, keys: list[str], fields: dict[str, FieldSpec], seq_len: int):
    """One MGET of the distinct keys -> (fields [B, T, ...], mask [B, T] bool,
    missing rows (key gone: evicted since it was drawn), corrupt rows)."""
    uniq = list(dict.fromkeys(keys))
    pos = {k: i for i, k in enumerate(uniq)}
    raws = r.mget(uniq) if uniq else []
    U = len(uniq)
    out = {k: np.empty((U, seq_len, *s.shape), dtype=s.dtype) for k, s in fields.items()}
    mask = np.zeros((U, seq_len), dtype=bool)
    state = np.zeros(U, np.int8)  # 0 ok, 1 missing, 2 corrupt
    for i, raw in enumerate(raws):
        if raw is None:
            state[i] = 1
            continue
        try:
            arrs, _ = decode_checked(raw, fields, seq_len)
        except CodecError:
            state[i] = 2
            continue
        for k in fields:
            out[k][i] = arrs[k]
        mask[i] = arrs["_mask"]
    inv = np.array([pos[k] for k in keys], dtype=np.int64)
    if U == len(keys):  # no duplicates: rows are already in order
        return out, mask, np.flatnonzero(state == 1), np.flatnonzero(state == 2)
    st = state[inv]
    return {k: v[inv] for k, v in out.items()}, mask[inv], np.flatnonzero(st == 1), np.flatnonzero(st == 2)


# -- the shard's side -------------------------------------------------------------------------
class RedisStorage:
    durable = True

    def __init__(self, fields: dict[str, FieldSpec], capacity: int, seq_len: int, client: redis.Redis,
                 namespace: str) -> None:
        self.fields, self.capacity, self.T = dict(fields), capacity, seq_len
        self.r = client
        self.ns = namespace
        self.keys: list[str | None] = [None] * capacity  # [C] record key per slot
        meta = {k.decode(): v.decode() for k, v in self.r.hgetall(f"{self.ns}:meta").items()}
        if meta:
            if int(meta.get("capacity", capacity)) != capacity or int(meta.get("seq_len", seq_len)) != seq_len:
                raise ValueError(
                    f"redis namespace {self.ns} holds capacity={meta.get('capacity')} seq_len={meta.get('seq_len')}, "
                    f"this shard has capacity={capacity} seq_len={seq_len}")
        else:
            self.r.hset(f"{self.ns}:meta", mapping={"count": 0, "capacity": capacity, "seq_len": seq_len})

    @property
    def nbytes(self) -> int:
        return 0  # the bytes live in redis-server

    def _register_cmds(self, p, slots: np.ndarray, keys: list[str], meta: dict[str, np.ndarray]) -> list[str]:
        idx, prio, old = {}, {}, []
        for row, slot in enumerate(slots):
            s = int(slot)
            idx[s] = msgpack.packb([keys[row], int(meta["stamp"][row]), int(meta["version"][row]),
                                    int(meta["episode"][row]), int(meta["steps"][row])])
            prio[s] = repr(float(meta["priority"][row]))
            if self.keys[s] is not None and self.keys[s] != keys[row]:
                old.append(self.keys[s])  # evicted record
        p.hset(f"{self.ns}:idx", mapping=idx)
        p.hset(f"{self.ns}:prio", mapping=prio)
        p.hset(f"{self.ns}:meta", "count", int(meta["stamp"][-1]) + 1)
        if old:
            p.delete(*old)
        return old

    def write(self, slots: np.ndarray, batch: SequenceBatch, meta: dict[str, np.ndarray]) -> None:
        """Records and index together (the in-process path)."""
        keys = new_keys(self.ns, len(slots))
        p = self.r.pipeline(transaction=True)
        p.mset(dict(zip(keys, encode_rows(batch, np.arange(len(slots))))))
        self._register_cmds(p, slots, keys, meta)
        p.execute()
        for s, k in zip(slots, keys):
            self.keys[int(s)] = k

    def register(self, slots: np.ndarray, keys: list[str], meta: dict[str, np.ndarray]) -> None:
        """Index records a client already wrote (the direct path)."""
        if keys and self.r.exists(*set(keys)) != len(set(keys)):
            # a restart of this shard between the client's write and this call removed them as
            # unacknowledged: refuse, so the insert is not acknowledged (the client writes again)
            raise RecordsMissing(f"{self.ns}: records to index are gone; write them again")
        p = self.r.pipeline(transaction=True)
        self._register_cmds(p, slots, keys, meta)
        p.execute()
        for s, k in zip(slots, keys):
            self.keys[int(s)] = k

    def discard_keys(self, keys: list[str]) -> None:
        """Delete records that will never be indexed (dropped before indexing)."""
        if keys:
            self.r.delete(*keys)

    def key_of(self, slots: np.ndarray) -> list[str]:
        return [self.keys[int(s)] for s in slots]

    def read(self, slots: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """-> (fields [B, T, ...], mask [B, T] bool, rows whose record is missing or corrupt)"""
        data, mask, missing, corrupt = fetch_records(self.r, self.key_of(slots), self.fields, self.T)
        return data, mask, np.union1d(missing, corrupt)

    def drop(self, slots: np.ndarray) -> None:
        """Forget slots whose record is unreadable (index entry and record)."""
        slots = [int(s) for s in slots]
        old = [self.keys[s] for s in slots if self.keys[s] is not None]
        p = self.r.pipeline(transaction=True)
        p.hdel(f"{self.ns}:idx", *slots)
        p.hdel(f"{self.ns}:prio", *slots)
        if old:
            p.delete(*old)
        p.execute()
        for s in slots:
            self.keys[s] = None

    def write_fields(self, slots: np.ndarray, fields: dict[str, np.ndarray]) -> None:
        keys = self.key_of(slots)
        recs = {}
        for row, (key, raw) in enumerate(zip(keys, self.r.mget(keys))):
            try:
                arrs, meta = decode_checked(raw, self.fields, self.T) if raw is not None else (None, None)
            except CodecError:
                arrs = None
            if arrs is None:
                continue  # gone or corrupt: left for sample/load to count
            arrs.update({k: v[row] for k, v in fields.items()})
            recs[key] = encode_record(arrs, meta)  # same key: the record's identity is unchanged
        if recs:
            self.r.mset(recs)

    def write_priorities(self, slots: np.ndarray, priorities: np.ndarray) -> None:
        if len(slots):
            self.r.hset(f"{self.ns}:prio", mapping={int(s): repr(float(p)) for s, p in zip(slots, priorities)})

    def load(self, chunk: int = 16) -> tuple[dict[str, np.ndarray], int, dict[str, int]]:
        """Rebuild from redis -> (index arrays [capacity] incl. priority, count, drops by reason)."""
        C = self.capacity
        idx = {"stamp": np.full(C, -1, np.int64), "version": np.zeros(C, np.int64),
               "episode": np.zeros(C, np.int64), "steps": np.zeros(C, np.int64),
               "priority": np.full(C, np.nan)}  # NaN = no stored priority
        self.keys = [None] * C
        corrupt, entries, entries_bad = 0, {}, []
        for s, v in self.r.hgetall(f"{self.ns}:idx").items():
            try:
                s = int(s)
                e = msgpack.unpackb(v, raw=False)
                ok = (0 <= s < C and isinstance(e, list) and len(e) == 5 and isinstance(e[0], str)
                      and e[0].startswith(f"{self.ns}:r:") and all(isinstance(x, int) for x in e[1:]))
            except Exception:  # msgpack raises several types for bad input
                ok = False
            if not ok:
                corrupt += 1
                entries_bad.append(s)
                continue
            entries[s] = e
        slots, bad_slots = sorted(entries), [s for s in entries_bad]
        for start in range(0, len(slots), chunk):  # check every record decodes
            part = slots[start:start + chunk]
            for s, raw in zip(part, self.r.mget([entries[x][0] for x in part])):
                try:
                    if raw is None:
                        raise CodecError("record missing")
                    _, meta = decode_checked(raw, self.fields, self.T)
                    if meta["steps"] != entries[s][4]:
                        raise CodecError("record disagrees with its index entry")
                except CodecError:
                    corrupt += 1
                    bad_slots.append(s)
                    continue
                key, idx["stamp"][s], idx["version"][s], idx["episode"][s], idx["steps"][s] = entries[s]
                self.keys[s] = key
        for s, v in self.r.hgetall(f"{self.ns}:prio").items():
            try:
                s, v = int(s), float(v)
            except ValueError:
                continue
            if 0 <= s < C and idx["stamp"][s] >= 0 and math.isfinite(v) and v >= 0:
                idx["priority"][s] = v
        known = {k for k in self.keys if k is not None}
        named = {e[0] for e in entries.values()}  # corrupt ones were counted already
        found = [x.decode() for x in self.r.scan_iter(match=f"{self.ns}:r:*", count=1000)]
        orphans = [k for k in found if k not in named]
        self.discard_keys(orphans + [k for k in found if k in named and k not in known])
        if bad_slots:
            self.r.hdel(f"{self.ns}:idx", *bad_slots)
        count = int(self.r.hget(f"{self.ns}:meta", "count") or 0)
        count = max(count, int(idx["stamp"].max()) + 1)
        return idx, count, {"corrupt": corrupt, "unacked": len(orphans)}

    def clear(self) -> None:
        """Delete this shard's namespace (tests and fresh runs)."""
        keys = list(self.r.scan_iter(match=f"{self.ns}:*", count=1000))
        for i in range(0, len(keys), 1000):
            self.r.delete(*keys[i:i + 1000])

    def close(self) -> None:
        self.r.close()
