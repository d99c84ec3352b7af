"""Redis storage: sequence records live in redis-server; the shard keeps the index.

Keys are namespaced by run and shard (`wmdist:<run>:s<shard>:...`):

- `...:r:<token>` string: `codec.encode_record` of one sequence (`[T, ...]` per field plus
  `_mask`, and metadata version / episode / steps). Tokens are unique, so a key never
  changes meaning: a reader holding an old key finds the old record or nothing.
- `...:pending` list: msgpack [keys, versions, episodes, steps, policy-lag drops], one entry
  per client insert, pushed after its records by a script that checks they are all there
  (`commit_records`); the shard indexes and trims it (`read_pending`, `register(consumed=...)`);
- `...:idx`  hash slot -> msgpack [key, stamp, version, episode, steps]: the shard's index;
- `...:prio` hash slot -> priority (raw, before alpha);
- `...:meta` hash: `count` (sequences ever indexed; the next slot is count % capacity),
  `capacity`, `seq_len` (a restart with another layout is refused).

Data path: record bytes can be written and read by any process (`commit_records`,
`fetch_records`: one pipeline of SETs + the announcements / one MGET), so collectors and
the learner move bytes to and from redis directly while the shard actor only indexes keys.
Records of one schema are encoded and decoded through a precomputed `RecordLayout` (the
codec's bytes, without walking msgpack per array). The shard's own `write` (used
in-process) is records + register in one MULTI/EXEC.

Durability: a client insert (`commit_records`: a pipeline of SETs, then a small script that
pushes the pending entry only if every record is there) is acknowledged once it returns;
under `appendfsync always` that is after the fsync covering all of it. The shard indexes
pending entries later: `register` is one MULTI/EXEC (index, priorities, count, DEL of the records it
evicts, LTRIM of the entries it consumed), so an entry is indexed exactly once even if the
shard dies half-way. `load()` rebuilds the index and priorities after a restart, skips and
counts records that fail to decode, and deletes records that neither the index nor a
pending entry names (written by an insert that was never announced, so never acknowledged;
`_sweep` makes that safe against inserts running meanwhile); the shard then indexes the
pending entries, so acknowledged inserts survive a shard restart.
"""
from __future__ import annotations

import math
import uuid

import msgpack
import numpy as np
import redis

from wmdist.algos.base import FieldSpec
from wmdist.replay import resp
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.codec import CodecError, encode_record
from wmdist.replay.layout import RecordLayout, layout_for, schema_of


def connect(url: str, password_file: str = "") -> redis.Redis:
    """A redis client for `url`, with the password read from `password_file` if given."""
    if not url.startswith(("redis://", "rediss://", "unix://")):
        raise ValueError(f"replay.redis_url must start with redis://, rediss:// or unix://, got {url!r}")
    kw = {}
    if password_file:
        with open(password_file, encoding="utf-8") as f:
            kw["password"] = f.read().strip()
    client = redis.Redis.from_url(url, socket_timeout=60, socket_connect_timeout=10, health_check_interval=30, **kw)
    pool = client.connection_pool  # no connection made yet: every one it makes sends in bulk
    pool.connection_class = _bulk_class(pool.connection_class)
    return client


# redis-py sends every argument above 6,000 bytes as its own write (one syscall each): an insert
# of 32 vector records (~6.2 KB each) made ~65 of them, a quarter of its time. Joined up to
# 64 KiB, it makes ~4; records larger than that (pixels) still go out uncopied, one write each.
SEND_CHUNK = resp.CHUNK  # 64 KiB, the same as the replay's own packing (`resp.pack`)


def _bulk_class(cls: type) -> type:
    """`cls` (the URL's connection class: TCP, TLS or unix socket) joining writes up to SEND_CHUNK."""
    def __init__(self, *args, **kwargs) -> None:
        cls.__init__(self, *args, **kwargs)
        self._buffer_cutoff = SEND_CHUNK  # redis-py's own threshold for sending an argument alone

    return type(f"Bulk{cls.__name__}", (cls,), {"__init__": __init__})


class RecordsMissing(RuntimeError):
    """`register` found some of the records it should index missing."""


# -- records (any process) ------------------------------------------------------------------
def batch_layout(batch: SequenceBatch) -> RecordLayout:
    """The record layout of a batch's schema (fields as the batch holds them)."""
    return layout_for(schema_of({k: _Spec(v.shape[2:], v.dtype) for k, v in batch.data.items()},
                                batch.mask.shape[1]))


class _Spec:  # FieldSpec-like view of an array column (shape without [N, T])
    def __init__(self, shape: tuple[int, ...], dtype: np.dtype) -> None:
        self.shape, self.dtype = tuple(shape), dtype


def encode_rows(batch: SequenceBatch, rows: np.ndarray, steps: np.ndarray | None = None) -> list[bytes]:
    """One record per selected window of the batch (`codec.encode_record` bytes), copied
    straight from the batch's arrays; `steps` [N]: real steps per window if known."""
    rows = np.asarray(rows, np.int64).tolist()
    steps = (batch.mask.sum(axis=1) if steps is None else steps).tolist()
    version, episode = batch.version.tolist(), batch.episode_id.tolist()
    meta = [{"version": version[r], "episode": episode[r], "steps": steps[r]} for r in rows]
    return batch_layout(batch).encode_rows(batch.data, batch.mask, meta, rows)


def pending_entry(keys: list[str], version: np.ndarray, episode: np.ndarray, steps: np.ndarray,
                  lag_drops: int = 0) -> bytes:
    """The announcement of one client insert to a shard (see `...:pending`)."""
    cols = [np.asarray(c, np.int64).tolist() for c in (version, episode, steps)]
    return msgpack.packb([list(keys), *cols, int(lag_drops)])


# A client insert's index write: announce the records to their shard (RPUSH of the pending
# entry) only if every one of them is there. KEYS: the records, then the pending list; ARGV:
# the entry. A restarting shard deletes records that nothing names (`RedisStorage.load`); if
# it did between this insert's SETs and this script, the insert is refused (0) and whatever
# is left of its records deleted, so nothing half-written ever becomes visible.
_ANNOUNCE = b"""
local n = #KEYS - 1
for i = 1, n do
  if redis.call('EXISTS', KEYS[i]) == 0 then
    for j = 1, n do redis.call('DEL', KEYS[j]) end
    return 0
  end
end
redis.call('RPUSH', KEYS[n + 1], ARGV[1])
return 1
"""


BIG_WRITE = 1 << 20  # bytes: above, an insert's records go as one SET each (see `commit_records`)


def commit_records(r: redis.Redis, writes: list[tuple[str, dict[str, bytes], bytes]]) -> list[int]:
    """Write every shard's records, then announce each shard's (`writes`: namespace, records,
    pending entry) -> indices of the writes refused (their records were swept by a shard
    restart in between: write them again under new keys).

    One pipeline, no transaction: the SETs are run as their bytes arrive (a MULTI/EXEC would
    hold megabytes of pixels until EXEC), and the small `_ANNOUNCE` script after them makes
    each shard's records visible at once, only if all of them are there. Acknowledged when it
    returns; under `appendfsync always` redis replies after the fsync that covers every
    command before. A crash before the announcement leaves records nothing names: the
    shard's next `load` deletes them (counted `unacked`)."""
    keys = [[k.encode() for k in recs] for _, recs, _ in writes]  # each encoded once, used twice
    records = [(k, v) for ks, (_, recs, _) in zip(keys, writes) for k, v in zip(ks, recs.values())]
    cmds: list[tuple] = []  # (records may be empty: an insert whose rows all lagged)
    if records and sum(len(v) for _, v in records) <= BIG_WRITE:
        # small: one command parses and runs cheaper than one per record
        cmds.append((b"MSET", *[x for kv in records for x in kv]))
    else:
        cmds += [(b"SET", k, v) for k, v in records]  # big: each runs while the next is on the wire
    cmds += [(b"EVAL", _ANNOUNCE, len(ks) + 1, *ks, f"{ns}:pending", entry)
             for ks, (ns, _, entry) in zip(keys, writes)]
    replies = resp.execute(r, cmds)  # raises: not acknowledged (announced or not, it is never half-visible)
    return [i for i, ok in enumerate(replies[len(replies) - len(writes):]) if ok != 1]


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
    return layout_for(schema_of(fields, seq_len)).decode_one(raw)


def fetch_records(r: redis.Redis, keys: list[str], fields: dict[str, FieldSpec], seq_len: int,
                  layout: RecordLayout | None = None):
    """One MGET of the distinct keys -> (fields [B, T, ...], mask [B, T] bool,
    missing rows (key gone: evicted since it was drawn), corrupt rows). `layout`: the
    fields' `RecordLayout` if the caller keeps one (saves building the schema per call)."""
    uniq = list(dict.fromkeys(keys))
    raws = r.mget(uniq) if uniq else []
    if len(uniq) < len(keys):  # a key drawn twice: decode its bytes into each row (no regather)
        got = dict(zip(uniq, raws))
        raws = [got[k] for k in keys]
    out, state, _ = (layout or layout_for(schema_of(fields, seq_len))).decode_many(raws)
    mask = out.pop("_mask")
    return out, mask, np.flatnonzero(state == 1), np.flatnonzero(state == 2)


def _parse_entry(raw: bytes, prefix: str, seq_len: int) -> tuple | None:
    """A pending entry -> (keys, version, episode, steps [n] int64, lag_drops), None if malformed."""
    try:
        e = msgpack.unpackb(raw, raw=False, strict_map_key=True)
    except Exception:  # msgpack raises several types for bad input
        return None
    if not (isinstance(e, list) and len(e) == 5 and all(isinstance(x, list) for x in e[:4])
            and isinstance(e[4], int) and e[4] >= 0):
        return None
    keys, cols = e[0], e[1:4]
    if (not all(isinstance(k, str) and k.startswith(prefix) for k in keys)
            or any(len(c) != len(keys) or not all(type(x) is int for x in c) for c in cols)
            or not all(1 <= x <= seq_len for x in cols[2])):
        return None
    return (keys, *(np.array(c, np.int64) for c in cols), e[4])


# -- the shard's side -------------------------------------------------------------------------
class RedisStorage:
    durable = True

    def __init__(self, fields: dict[str, FieldSpec], capacity: int, seq_len: int, client: redis.Redis,
                 namespace: str) -> None:
        self.fields, self.capacity, self.T = dict(fields), capacity, seq_len
        self.r = client
        self.ns = namespace
        self.layout = layout_for(schema_of(fields, seq_len))
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

    def register(self, slots: np.ndarray, keys: list[str], meta: dict[str, np.ndarray], consumed: int = 0,
                 discard: list[str] = (), check: bool = True) -> None:
        """Index records a client already wrote (the direct path). `consumed` pending entries
        are trimmed and `discard` records deleted in the same MULTI/EXEC. With `check`, refuse
        keys whose records are gone (`insert_keys`: the client writes them again)."""
        if check and keys and self.r.exists(*set(keys)) != len(set(keys)):
            # a restart of this shard between the client's write and this call removed them as
            # unacknowledged: refuse, so the insert is not acknowledged (the client writes again)
            raise RecordsMissing(f"{self.ns}: records to index are gone; write them again")
        p = self.r.pipeline(transaction=True)
        if len(slots):
            self._register_cmds(p, slots, keys, meta)
        if consumed:
            p.ltrim(f"{self.ns}:pending", consumed, -1)
        if discard:
            p.delete(*discard)
        p.execute()
        for s, k in zip(slots, keys):
            self.keys[int(s)] = k

    def read_pending(self, limit: int = 1024) -> tuple[list[tuple], int, int]:
        """Up to `limit` announced client inserts, oldest first -> (valid entries as
        (keys, version, episode, steps, lag_drops), entries read, malformed entries)."""
        raws = self.r.lrange(f"{self.ns}:pending", 0, limit - 1)
        good, bad = [], 0
        for raw in raws:
            e = _parse_entry(raw, f"{self.ns}:r:", self.T)
            if e is None:
                bad += 1
            else:
                good.append(e)
        return good, len(raws), bad

    def discard_keys(self, keys: list[str]) -> None:
        """Delete records that will never be indexed (dropped before indexing)."""
        if keys:
            self.r.delete(*keys)

    def key_of(self, slots: np.ndarray) -> list[str]:
        return [self.keys[int(s)] for s in slots]

    def read(self, slots: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """-> (fields [B, T, ...], mask [B, T] bool, rows whose record is missing or corrupt)"""
        data, mask, missing, corrupt = fetch_records(self.r, self.key_of(slots), self.fields, self.T, self.layout)
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
                arrs, meta = self.layout.decode_one(raw) if raw is not None else (None, None)
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

    def load(self, chunk: int = 64) -> tuple[dict[str, np.ndarray], int, dict[str, int]]:
        """Rebuild from redis -> (index arrays [capacity] incl. priority, count, drops by reason)."""
        C = self.capacity
        # records first, then the index and pending entries: a record written while we scan
        # is either announced by the time `_sweep` reads the pending list, or its announcement
        # finds it swept and is refused (the client writes it again)
        found = [x.decode() for x in self.r.scan_iter(match=f"{self.ns}:r:*", count=1000)]
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
            _, _, metas = self.layout.decode_many(self.r.mget([entries[x][0] for x in part]))
            for s, meta in zip(part, metas):
                if meta is None or meta["steps"] != entries[s][4]:  # missing, corrupt or disagreeing
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
        self.discard_keys([k for k in found if k in named and k not in known])
        orphans = self._sweep([k for k in found if k not in named])
        if bad_slots:
            self.r.hdel(f"{self.ns}:idx", *bad_slots)
        count = int(self.r.hget(f"{self.ns}:meta", "count") or 0)
        count = max(count, int(idx["stamp"].max()) + 1)
        return idx, count, {"corrupt": corrupt, "unacked": len(orphans)}

    def _sweep(self, unindexed: list[str], tries: int = 100) -> list[str]:
        """Delete the records that no pending entry names either (written by inserts that were
        never announced: not acknowledged) -> those deleted. The pending list is WATCHed from
        its read to the DEL, so an announcement in between makes us read it again; one that
        comes after finds its records gone and is refused (`_ANNOUNCE`): a record is never
        deleted under an announcement. Gives up (deletes nothing) if announcements keep coming."""
        if not unindexed:
            return []
        key = f"{self.ns}:pending"
        with self.r.pipeline(transaction=True) as p:
            for _ in range(tries):
                try:
                    p.watch(key)
                    named = {k for raw in p.lrange(key, 0, -1)
                             for k in (_parse_entry(raw, f"{self.ns}:r:", self.T) or [[]])[0]}
                    orphans = [k for k in unindexed if k not in named]
                    p.multi()
                    for i in range(0, len(orphans), 1000):
                        p.delete(*orphans[i:i + 1000])
                    p.execute()
                    return orphans
                except redis.WatchError:
                    continue
        return []

    def clear(self) -> None:
        """Delete this shard's namespace (tests and fresh runs)."""
        keys = list(self.r.scan_iter(match=f"{self.ns}:*", count=1000))
        for i in range(0, len(keys), 1000):
            self.r.delete(*keys[i:i + 1000])

    def close(self) -> None:
        self.r.close()
