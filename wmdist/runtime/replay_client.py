"""ReplayClient: what collectors, the learner and reanalyzers hold to use the replay service.

A small picklable object with the shard and limiter actor handles. Only the process that
called `create_replay` owns the service (its `close()` stops the actors and the private
redis-server); a pickled copy's `close()` only stops that copy.

With `backend: redis` every process holding a client reads and writes record bytes in
redis itself (see `wmdist/replay/__init__.py`), so it must reach the server: the private
server (no `redis_url`) binds 127.0.0.1 and suits single-node runs; a multi-node run names a
reachable server in `replay.redis_url` with `replay.redis_password_file` on every node.

Stats keys (`stats()`), all floats:
  `size_steps`, `size_sequences`, `capacity_sequences`, `inserts`, `samples`, `bytes` (memory
  backend: ring arrays + index; redis: index only) -- summed over shards;
  `stale_reads` (shared memory only: rows a reader found rewritten after its draw, drawn again);
  (`samples` includes unlimited reanalyzer draws; the limiter's own counts do not);
  `drops_<reason>` summed, reason in stale_writeback, stale_priority, evicted, corrupt,
  policy_lag, unacked; the same keys per shard as `shard<i>_<key>`;
  limiter: `insert_wait_seconds`, `sample_wait_seconds`, `limiter_error` (S - I*spi),
  `limiter_inserted`, `limiter_sampled`, `limiter_size_steps` (steps ever stored),
  `policy_version`.
"""
from __future__ import annotations

import json
import os
import secrets
import threading
import time

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import Sample, SequenceBatch, make_keys, split_keys, step_ages
from wmdist.replay.coalesce import Coalescer
from wmdist.replay.config import ReplayConfig
from wmdist.replay.draws import DrawPools, is_weights
from wmdist.replay.layout import layout_for, schema_of
from wmdist.replay.shard import DROP_REASONS
from wmdist.replay.stock import GatheredStock, Pace, batches_ahead
from wmdist.replay.storage_redis import (
    RecordsMissing,
    commit_records,
    connect,
    encode_rows,
    fetch_records,
    new_keys,
    pending_entry,
)
from wmdist.replay.shm import drop as drop_segment
from wmdist.replay.shm import keep_with_process, segment_prefix, sweep
from wmdist.runtime.calls import LocalHandle, actor_died, get, kill
from wmdist.runtime.named import NamedHandle, start_named
from wmdist.runtime.replay_shm import ShmPath, StaleSegment, node_id


def route(source_id: int, episode_id: np.ndarray, shards: int) -> np.ndarray:
    """Shard of each episode: a 64-bit mix of (collector id, episode id) modulo S."""
    with np.errstate(over="ignore"):
        h = np.uint64(source_id) * np.uint64(0x9E3779B97F4A7C15) ^ episode_id.astype(np.uint64)
        h = (h ^ (h >> np.uint64(31))) * np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    return (h % np.uint64(shards)).astype(np.int64)


# drawn paths (redis, shared memory): each shard is asked for its share of S x this many samples'
# worth of draws at a time, at least this many samples before they are needed, so the union of
# shards costs one call per this many samples (a shard call costs ~1 ms of this process's time and
# can take 10+ ms to come back on a loaded machine)
PREFETCH_SAMPLES = 16
MAX_DRAW_AGE = 1.0  # seconds: older draws are dropped, so a slow reader sees fresh contents


class ReplayClient:
    def __init__(self, cfg: ReplayConfig, fields: dict[str, FieldSpec], shards: list, limiter, server=None,
                 redis_url: str = "", password_file: str = "", namespaces: list[str] | None = None,
                 segments: list[str] | None = None) -> None:
        self.cfg, self.fields = cfg, dict(fields)
        self.shards, self.limiter = list(shards), limiter
        self._server = server  # private redis-server (owner only)
        self._redis_url, self._password_file = redis_url, password_file
        self._namespaces = list(namespaces or [])  # per shard (redis backend)
        self._redis = None  # connection, opened lazily in each process
        self._owner = True
        self._closed = False
        self._rng: np.random.Generator | None = None
        self._warm = False  # this copy saw min_size reached with the ratio off
        # counts that gate nothing, sent to the limiter at most every 50 ms on this copy's own
        # thread (`coalesce.py`); flushed before every blocking limiter call, stats, save, close
        self._inserts: Coalescer | None = None  # (sequences, steps) of inserts with ratio and lag off
        self._samples: Coalescer | None = None  # sequences sampled once warm
        self._capacity = shard_capacity(cfg, fields)  # sequence slots per shard
        # redis: draws taken ahead per shard (see `wmdist/replay/draws.py`); `_gen` counts this
        # copy's writes, and draws taken before one of them are dropped (read-your-writes)
        self._draws: DrawPools | None = None  # built in the process that samples
        self._gen, self._pool_gen = 0, 0
        self._layout = None  # the fields' RecordLayout (redis), built on first use
        self._draw_lock: threading.Lock | None = None
        self._stock: GatheredStock | None = None  # rows gathered for the next samples (`replay/stock.py`)
        self._pace = Pace(most=cfg.sample_ahead)  # this copy's recent sample calls, counted up to sample_ahead
        self.gathers = 0  # row gathers this copy made on the drawn paths (one per stock)
        self._seq_bytes = sum(int(np.prod(s.shape)) * np.dtype(s.dtype).itemsize for s in fields.values()) \
            * cfg.seq_len + cfg.seq_len  # one sequence's rows and mask
        self._batches = 0  # rate-limited (learner) batches this copy sampled: anneals beta
        # memory backend: the shards' shared-memory segments, mapped in the process that uses
        # them (`replay_shm.ShmPath`); None where they are out of reach (rows go by actor call)
        self._shm: ShmPath | None = None
        self._shm_tried = False
        self._segments = list(segments or [])  # owner: segment names its resource tracker holds

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.update(_server=None, _owner=False, _rng=None, _redis=None, _warm=False, _samples=None,
                     _draws=None, _draw_lock=None, _stock=None, _pace=Pace(most=self.cfg.sample_ahead), gathers=0,
                     _layout=None, _inserts=None, _shm=None, _shm_tried=False,
                     _segments=[])
        return state

    @property
    def direct(self) -> bool:
        """Redis backend: this client moves record bytes to and from redis itself."""
        return self.cfg.backend == "redis"

    def _shm_path(self) -> ShmPath | None:
        """This process's mapping of the shards' segments (memory backend with `shm` on and
        every shard on this node), made on first use; None: rows go through actor calls."""
        if self._shm is not None and self._shm.broken:  # a shard recreated its segment: map again
            self._drop_shm()
        if self._shm is None and not self._shm_tried and self.cfg.backend == "memory" and self.cfg.shm:
            self._shm_tried = True
            self._shm = ShmPath.connect(self.shards, self.fields, self.cfg.seq_len, self._capacity)
        return self._shm

    def _drop_shm(self) -> None:
        if self._shm is not None:
            self._shm.close()
        self._shm, self._shm_tried, self._stock = None, False, None
        if self._draws is not None:
            self._draws.clear()

    @property
    def redis(self):
        if self._redis is None:
            self._redis = connect(self._redis_url, self._password_file)
        return self._redis

    @property
    def rng(self) -> np.random.Generator:
        if self._rng is None:
            self._rng = np.random.default_rng([self.cfg.seed, os.getpid()])
        return self._rng

    # -- insert -------------------------------------------------------------------------
    def insert(self, batch: SequenceBatch, source_id: int, timeout: float | None = None) -> bool:
        """Store complete windows; False if the limiter kept it waiting past `timeout` (or closed)."""
        if self._closed:
            return False
        batch.validate(self.fields, self.cfg.seq_len)  # the caller gets the clear error
        n = len(batch)
        if n == 0:
            return True
        lag = self.cfg.max_policy_lag
        free = self.cfg.samples_per_insert == 0 and lag == 0  # never waits: counted afterwards, no round trip
        try:
            if not free:
                self._flush_counts()  # the limiter decides on every count this copy made
            ok, version = (True, -1) if free else get(self.limiter.acquire_insert.remote(n, timeout))
        except actor_died():
            return False  # the service was shut down
        if not ok:
            return False
        min_version = version - lag if lag > 0 and version >= 0 else None
        dest = route(source_id, batch.episode_id, len(self.shards))
        if self.direct:
            steps = self._insert_direct(batch, dest, min_version)
            self._gen += 1  # the next sample draws afresh, so it sees these
        elif self._shm_path() is not None:  # rows into shared memory; no shard call on the way, mostly
            if self._shm.closed:
                return False  # the service was shut down
            keep = np.ones(n, bool) if min_version is None else batch.version >= min_version
            steps = self._shm.insert(batch, dest, keep, batch.mask.sum(axis=1).astype(np.int64))
            self._gen += 1
        else:  # one batched call per shard; Ray carries the arrays
            targets = np.unique(dest)
            steps = sum(get([self.shards[s].insert.remote(
                batch if targets.size == 1 else batch.select(np.flatnonzero(dest == s)), min_version)
                for s in targets]))
        if free:  # gates nothing: summed and sent at most every 50 ms (a Ray call costs ~1 ms here)
            if self._inserts is None:
                self._inserts = Coalescer(lambda k, st: self.limiter.record_insert.remote(k, st), 2, wait=_settle)
            self._inserts.add(n, steps)
        else:
            self.limiter.commit_insert.remote(steps)
        return True

    def _insert_direct(self, batch: SequenceBatch, dest: np.ndarray, min_version: int | None) -> int:
        """Every shard's records, then its pending entry, go to redis in one pipeline (one
        round trip; see `commit_records`), with no shard call. The shards index the entries
        later (on their next read or drain tick); a shard restart in between indexes them on
        reload. Returns the real steps the shards will keep."""
        keep = np.ones(len(batch), bool) if min_version is None else batch.version >= min_version
        steps = batch.mask.sum(axis=1).astype(np.int64)
        if steps.min() < 1:  # the shards' pending entries require real steps in [1, T]
            raise ValueError("replay insert: a window has no real step (its mask is all 0)")
        cap = self._capacity
        parts, stored = [], 0  # (shard, rows, policy-lag drops)
        for s in np.unique(dest):
            rows = np.flatnonzero((dest == s) & keep)
            lag = int(((dest == s) & ~keep).sum())
            if rows.size or lag:
                parts.append((int(s), rows, lag))
                stored += int(steps[rows][-cap:].sum()) if rows.size else 0  # a shard keeps its newest `cap`
        for _ in range(3):  # refused only if a shard restart swept the records mid-insert
            writes = []
            for s, rows, lag in parts:
                keys = new_keys(self._namespaces[s], rows.size)
                entry = pending_entry(keys, batch.version[rows], batch.episode_id[rows], steps[rows], lag)
                writes.append((self._namespaces[s], dict(zip(keys, encode_rows(batch, rows, steps))), entry))
            refused = commit_records(self.redis, writes)
            if not refused:
                return stored
            parts = [parts[i] for i in refused]  # written again under new keys
        # (the shards that accepted keep their part: like a crash between shards' inserts)
        raise RecordsMissing("replay insert: records kept vanishing before their announcement (shard restarts)")

    # -- sample -------------------------------------------------------------------------
    def sample(self, batch_size: int, timeout: float | None = None, limited: bool = True) -> Sample | None:
        """B sequences from the union of shards; None if the limiter waited past `timeout`.

        `limited=False` (reanalyzers) bypasses the rate limiter, so refreshing targets does
        not count as training samples; it returns None while replay is empty."""
        if batch_size < 1:
            raise ValueError(f"sample batch_size must be >= 1, got {batch_size}")
        if self._closed:
            return None
        try:
            if limited and self._warm:  # ratio off and min_size reached (it stays reached): just count
                self._count_samples(batch_size)
            elif limited:
                self._flush_counts()  # e.g. this copy's own inserts towards min_size
                if not get(self.limiter.acquire_sample.remote(batch_size, timeout)):
                    return None
                self._warm = self.cfg.samples_per_insert == 0
            drawn = self.direct or self._shm_path() is not None  # draw pools, then the client reads
            if (not limited and not drawn
                    and sum(m[0] for m in get([s.mass.remote() for s in self.shards])) == 0):
                return None
        except actor_died():
            return None
        try:
            if self.direct:
                return self._sample_drawn(batch_size, limited, self._fetch_direct)
            if drawn:
                try:
                    return self._sample_drawn(batch_size, limited, self._fetch_shm)
                except StaleSegment:  # a shard recreated its segment: this once by call, then map again
                    self._drop_shm()
            return self._sample(batch_size)
        except actor_died():
            return None  # the service was shut down
        finally:
            self._batches += int(limited)  # beta counts the batches before this one

    def _count_samples(self, n: int) -> None:
        """Warm and ratio off, the count gates nothing: sent at most every 50 ms."""
        if self._samples is None:
            self._samples = Coalescer(lambda k: self.limiter.acquire_sample.remote(k, 0), 1, wait=_settle)
        self._samples.add(n)

    def _flush_counts(self, settle: bool = False) -> None:
        """Send every count held back (before a blocking limiter call); with `settle`, wait
        until the limiter applied them (before stats, save, close: the threaded limiter may
        run a later call of ours before an earlier one)."""
        for c in (self._inserts, self._samples):
            if c is not None:
                c.flush(settle)

    def _sample(self, batch_size: int) -> Sample:
        """Memory backend: each shard gathers its rows and Ray carries them back."""
        S = len(self.shards)
        if S == 1:
            counts, n, mass = np.array([batch_size]), 0, 0.0
        else:  # split B by size (uniform) or priority mass (prioritized) so shards act as one buffer
            masses = get([s.mass.remote() for s in self.shards])
            n = sum(m[0] for m in masses)
            mass = sum(m[1] for m in masses)
            if mass <= 0:
                raise ValueError("replay is empty (min_size 0 and nothing inserted)")
            counts = self.rng.multinomial(batch_size, np.array([m[1] for m in masses]) / mass)
        beta = self._beta
        parts = [(i, self.shards[i].sample.remote(int(k), beta, n, mass)) for i, k in enumerate(counts) if k > 0]
        got = get([r for _, r in parts])
        w = np.concatenate([g["is_weight"] for g in got])
        return Sample(
            data={f: np.concatenate([g["data"][f] for g in got]) for f in self.fields},
            mask=np.concatenate([g["mask"] for g in got]).astype(np.float32),
            is_weight=(w / w.max()).astype(np.float32),  # normalised by the batch max (Schaul et al. 2016)
            keys=make_keys(np.concatenate([np.full(len(g["slots"]), i) for (i, _), g in zip(parts, got)]),
                           np.concatenate([g["slots"] for g in got])),
            stamps=np.concatenate([g["stamps"] for g in got]),
            age=step_ages(np.concatenate([g["newer"] for g in got]), np.concatenate([g["mask"] for g in got]), S),
        )

    @property
    def _beta(self) -> float:
        """Prioritized: beta annealed linearly to 1 over `priority_beta_anneal_samples` batches."""
        if self.cfg.sampler != "prioritized":
            return 0.0
        b0, span = self.cfg.priority_beta, self.cfg.priority_beta_anneal_samples
        return b0 if span <= 0 else b0 + (1.0 - b0) * min(1.0, self._batches / span)

    def _sample_drawn(self, batch_size: int, limited: bool, fetch) -> Sample | None:
        """Redis backend and shared memory: draws from the pools (no shard round trip when the
        prefetched draws are back), then `fetch` reads the rows (one MGET / one compiled copy). A
        reader sampling back-to-back without writing gathers several batches at once and
        serves the next ones from that stock (`wmdist/replay/stock.py`)."""
        if self._draw_lock is None:
            self._draw_lock = threading.Lock()
        with self._draw_lock:
            now = time.monotonic()
            recent = self._pace.tick(now)
            st = self._stock
            if st is None or not st.serves(batch_size, self._gen, now, MAX_DRAW_AGE):
                steady = self._pool_gen == self._gen  # no write since the previous sample
                k = batches_ahead(recent, batch_size * self._seq_bytes, self.cfg.sample_ahead) if steady else 1
                st = self._stock = self._gather(k, batch_size, fetch, now)
                if st is None:
                    if not limited:
                        return None
                    raise ValueError("replay is empty (min_size 0 and nothing inserted)")
            cut = st.take(batch_size)
            if st.left() < batch_size:  # (a stock of one batch is done at once)
                self._stock = None
        w = is_weights(st.mass[cut], st.n, st.total, self._beta)
        return Sample(data={f: v[cut] for f, v in st.data.items()}, mask=st.mask[cut],
                      is_weight=(w / w.max()).astype(np.float32),  # normalised by the batch max
                      keys=make_keys(st.shard_of[cut], st.slots[cut]), stamps=st.stamps[cut], age=st.age[cut])

    def _gather(self, k: int, batch_size: int, fetch, now: float) -> GatheredStock | None:
        """k batches' draws and their rows in one go; None while every shard is empty."""
        got = self._take_draws(k * batch_size, ahead=max(4, PREFETCH_SAMPLES // k))
        if got is None:
            return None
        self.gathers += 1
        shard_of, slots, stamps, mass, keys, n, total, newer = got
        if k > 1 and shard_of[0] != shard_of[-1]:
            # the draws come in one block per shard: shuffled, so each batch served from the stock
            # mixes the shards as an i.i.d. sample of the union does (the fetch reads rows in any
            # shard order at the same cost; one batch needs no shuffle)
            perm = self.rng.permutation(shard_of.size)
            shard_of, slots, stamps, mass, newer = (a[perm] for a in (shard_of, slots, stamps, mass, newer))
            keys = [keys[i] for i in perm] if keys else keys
        else:
            slots, stamps, mass, newer = slots.copy(), stamps.copy(), mass.copy(), newer.copy()  # redraws rewrite them
        data, mask = fetch(keys, shard_of, slots, stamps, mass, newer)
        return GatheredStock(data, mask.astype(np.float32), step_ages(newer, mask, len(self.shards)), shard_of, slots,
                             stamps, mass, n, total, batch_size, self._gen, now)

    def _take_draws(self, n: int, ahead: int = PREFETCH_SAMPLES):
        """n draws from the per-shard pools (`draws.DrawPools`: a shard call on this path only
        when a pool runs short, usually the request sent ahead). When this copy wrote since its
        previous sample, the pools are voided (read your writes) and nothing is asked ahead,
        since the next write (e.g. a priority update each learner step) would void it too."""
        if self._draws is None:
            self._draws = DrawPools(len(self.shards), lambda s, k: self.shards[s].draw.remote(k), get,
                                    PREFETCH_SAMPLES, MAX_DRAW_AGE)
        steady = self._pool_gen == self._gen
        if not steady:  # this copy wrote since these were drawn: they may not reflect it
            self._draws.clear()
            self._pool_gen = self._gen
        return self._draws.take(n, self.rng, prefetch=steady, ahead=ahead)

    def _fetch_direct(self, keys, shard_of, slots, stamps, mass, newer):
        """One MGET of the drawn records. Rows whose record is gone or undecodable are reported
        to their shard (which drops and counts them unless the slot was rewritten since the
        draw, i.e. evicted) and drawn again from the same shard."""
        if self._layout is None:
            self._layout = layout_for(schema_of(self.fields, self.cfg.seq_len))
        data, mask, missing, corrupt = fetch_records(self.redis, keys, self.fields, self.cfg.seq_len, self._layout)
        redo = np.union1d(missing, corrupt)
        for _ in range(100):
            if redo.size == 0:
                return data, mask
            by_shard = [(s, redo[shard_of[redo] == s]) for s in np.unique(shard_of[redo])]
            get([self.shards[s].drop_corrupt.remote(slots[rows], stamps[rows]) for s, rows in by_shard])
            again = []
            for s, rows in by_shard:
                g = get(self.shards[s].draw.remote(rows.size))
                if len(g["slots"]) < rows.size:
                    raise ValueError(f"replay shard {s} is empty")
                d2, m2, miss2, corr2 = fetch_records(self.redis, g["keys"], self.fields, self.cfg.seq_len,
                                                    self._layout)
                for f in self.fields:
                    data[f][rows] = d2[f]
                mask[rows] = m2
                slots[rows], stamps[rows], newer[rows], mass[rows] = g["slots"], g["stamps"], g["newer"], g["mass"]
                again.append(rows[np.union1d(miss2, corr2)])
            redo = np.concatenate(again)
        raise RuntimeError("replay: could not read a batch from redis after 100 redraws")

    def _fetch_shm(self, keys, shard_of, slots, stamps, mass, newer):
        """Rows copied from the mapped segments; a row rewritten since its draw (evicted,
        or written meanwhile) is drawn again from its shard, which counts it (`stale_reads`)."""
        path = self._shm

        def redraw(s: int, rows: np.ndarray) -> None:
            g = get(self.shards[s].draw.remote(rows.size, rows.size))
            if g.get("seg") != path.segs[s].token:
                path.broken = True
                raise StaleSegment(f"replay shard {s} serves another shared-memory segment")
            if len(g["slots"]) < rows.size:
                raise ValueError(f"replay shard {s} is empty")
            slots[rows], stamps[rows], newer[rows], mass[rows] = g["slots"], g["stamps"], g["newer"], g["mass"]

        return path.gather(self.fields, self.cfg.seq_len, shard_of, slots, stamps, redraw)

    # -- write-back ---------------------------------------------------------------------
    def _by_shard(self, keys: np.ndarray, stamps: np.ndarray):
        keys, stamps = np.asarray(keys, np.int64), np.asarray(stamps, np.int64)
        if keys.shape != stamps.shape or keys.ndim != 1:
            raise ValueError("keys and stamps must be 1-D arrays of the same length")
        shard, slot = split_keys(keys)
        if keys.size and (shard.min() < 0 or shard.max() >= len(self.shards)):
            raise ValueError(f"key names a shard outside [0, {len(self.shards)})")
        for s in np.unique(shard):
            rows = np.flatnonzero(shard == s)
            yield int(s), rows, slot[rows], stamps[rows]

    def update_priorities(self, keys: np.ndarray, stamps: np.ndarray, priorities: np.ndarray) -> int:
        """New raw priorities [B] for sampled keys; stale ones are dropped and counted."""
        pr = np.asarray(priorities, np.float64)
        if pr.shape != np.shape(keys):
            raise ValueError(f"priorities shape {pr.shape} != keys shape {np.shape(keys)}")
        refs = [self.shards[s].update_priorities.remote(sl, st, pr[rows])
                for s, rows, sl, st in self._by_shard(keys, stamps)]
        applied = int(sum(get(refs)))
        self._gen += 1  # draws taken before this reflect the old priorities
        return applied

    def write_back(self, keys: np.ndarray, stamps: np.ndarray, fields: dict[str, np.ndarray]) -> int:
        """Overwrite stored fields [B, T, ...] of sampled keys; stale rows are dropped and counted."""
        refs = [self.shards[s].write_back.remote(sl, st, {k: v[rows] for k, v in fields.items()})
                for s, rows, sl, st in self._by_shard(keys, stamps)]
        applied = int(sum(get(refs)))
        self._gen += 1
        return applied

    def resync_limiter(self) -> bool:
        """Give a limiter Ray restarted the shards' stored size again (the driver asks every
        second). True when it had to."""
        if self._closed or get(self.limiter.sized.remote(), timeout=30):
            return False
        sizes = get([s.mass.remote() for s in self.shards], timeout=300)
        get(self.limiter.set_size.remote(sum(int(m[2]) for m in sizes)))
        return True

    def set_policy_version(self, version: int) -> None:
        """The learner's latest published version (drives `max_policy_lag`). Waited for: the
        limiter is a threaded actor, so a later call of this client could otherwise overtake it."""
        get(self.limiter.set_version.remote(int(version)))

    # -- stats, checkpoints, shutdown ---------------------------------------------------
    def stats(self) -> dict[str, float]:
        self._flush_counts(settle=True)
        per = get([s.stats.remote() for s in self.shards])
        out: dict[str, float] = {}
        for i, st in enumerate(per):
            for k, v in st.items():
                out[f"shard{i}_{k}"] = v
                out[k] = out.get(k, 0.0) + v
        for r in DROP_REASONS:
            out.setdefault(f"drops_{r}", 0.0)
        out.update(get(self.limiter.stats.remote()))
        return out

    def save(self, directory: str) -> None:
        """Shards write `shard<i>.npz` (memory: all data; redis: index only), plus limiter state."""
        self._flush_counts(settle=True)
        os.makedirs(directory, exist_ok=True)
        get([s.save.remote(os.path.join(os.path.abspath(directory), f"shard{i}.npz"))
                 for i, s in enumerate(self.shards)])
        state = get(self.limiter.state_dict.remote())
        tmp = os.path.join(directory, "limiter.json.tmp")
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(state, f)
        os.replace(tmp, os.path.join(directory, "limiter.json"))

    def restore(self, directory: str) -> None:
        """Load what `save` wrote (memory: exact contents; redis: re-reads redis) and the limiter."""
        with open(os.path.join(directory, "limiter.json"), encoding="utf-8") as f:
            state = json.load(f)
        if not isinstance(state, dict):
            raise ValueError(f"{directory}/limiter.json is not a limiter state")
        get([s.restore.remote(os.path.join(os.path.abspath(directory), f"shard{i}.npz"))
                 for i, s in enumerate(self.shards)])
        get(self.limiter.load_state_dict.remote(state))

    def revive_server(self) -> bool:
        """Owner with a private redis-server: start it again (same port, directory and AOF) if
        its process has died. True when it was restarted; the clients reconnect on their own."""
        if self._server is None or self._closed or self._server.alive:
            return False
        self._server.restart()
        return True

    @property
    def server_url(self) -> str:
        """Where the record bytes live ('' for the memory backend)."""
        return self._redis_url

    def close(self) -> None:
        """Owner: wake every waiter of the service (they return False/None), then stop the
        actors and the private redis-server. A pickled copy only stops using the service."""
        if self._closed:
            return
        self._closed = True
        try:
            self._flush_counts(settle=True)
        except Exception:  # noqa: BLE001 - the limiter is gone already
            pass
        if self._redis is not None:
            self._redis.close()
        if self._shm is not None:
            self._shm.close()
            self._shm = None
        if not self._owner:
            return
        try:
            get(self.limiter.close.remote(), timeout=30)
        except Exception:  # already gone: nothing left to wake
            pass
        try:
            get([s.close.remote() for s in self.shards], timeout=30)
        except Exception:
            pass
        for a in [*self.shards, self.limiter]:
            kill(a)
        for name in self._segments:  # unlinked by their shard's close; if that did not run, here
            drop_segment(name)
        if self._server is not None:
            self._server.stop()
            self._server = None


def _settle(refs: list) -> None:
    """Wait for count calls sent earlier (bounded: a limiter that does not answer is gone)."""
    get(refs, timeout=60)


def shard_capacity(cfg: ReplayConfig, fields: dict[str, FieldSpec]) -> int:
    """Sequence slots per shard from `capacity_steps` (and `capacity_bytes` if set)."""
    total = cfg.capacity_steps // cfg.seq_len
    if cfg.capacity_bytes:
        per_seq = cfg.seq_len * (1 + sum(int(np.prod(s.shape)) * np.dtype(s.dtype).itemsize for s in fields.values()))
        total = min(total, cfg.capacity_bytes // per_seq)
    cap = total // cfg.shards
    if cap < 1:
        raise ValueError(f"replay capacity ({cfg.capacity_steps} steps, {cfg.capacity_bytes} bytes) is less than "
                         f"one sequence per shard")
    return cap


def create_replay(cfg: ReplayConfig, fields: dict[str, FieldSpec], run_dir: str, run_name: str,
                  local: bool = False) -> ReplayClient:
    """Start the shard actors, the limiter and (redis with no URL) a private redis-server.

    Their resources and restart policy are the table's "replay" and "limiter" entries; with
    `local` they are plain objects behind `LocalHandle`s (the Ray-free local runner)."""
    from wmdist.runtime.table import BUILTIN, by_name

    cfg.validate()
    if not local:
        import ray

        if not ray.is_initialized():
            raise ValueError("create_replay needs Ray initialised first")
    cap = shard_capacity(cfg, fields)
    server, url, pwfile = None, "", ""
    if cfg.backend == "redis":
        if cfg.redis_url:
            url, pwfile = cfg.redis_url, cfg.redis_password_file
        else:
            from wmdist.replay.redis_server import RedisServer

            # dies with the driver (even on SIGKILL) when the driver is its main thread
            server = RedisServer(os.path.join(run_dir, "redis"), cfg.redis_appendfsync, cfg.redis_aof,
                                 die_with_parent=threading.current_thread() is threading.main_thread()).start()
            url, pwfile = server.url, server.password_file
    namespaces = [f"wmdist:{run_name}:s{i}" for i in range(cfg.shards)]
    shm = cfg.backend == "memory" and cfg.shm and not local
    segments = [f"{segment_prefix(run_name, run_dir)}s{i}" if shm else "" for i in range(cfg.shards)]
    token = secrets.randbits(62)  # this service's: a restarted shard re-attaches only its own segment
    if shm:
        sweep(segment_prefix(run_name, run_dir))  # left by an earlier start of this run (on this node)
    roles = by_name(BUILTIN)
    shard_role, limiter_role = roles["replay"], roles["limiter"]
    shard_args = [(fields, cfg.seq_len, cap, cfg.sampler, cfg.priority_alpha, i, cfg.seed + i,
                   cfg.backend, url, pwfile, namespaces[i], segments[i], token) for i in range(cfg.shards)]
    limiter_args = (cfg.samples_per_insert, cfg.min_size, cfg.error_buffer)
    try:
        if local:
            shards = [LocalHandle(shard_role.actor()(*a)) for a in shard_args]
            limiter = LocalHandle(limiter_role.actor()(*limiter_args))
        else:
            shards = [_named(shard_role, cfg, i, a) for i, a in enumerate(shard_args)]
            limiter = _named(limiter_role, cfg, 0, limiter_args)
        sizes = get([s.mass.remote() for s in shards])  # also waits for redis shards to rebuild
    except Exception:
        if server is not None:
            server.stop()
        raise
    get(limiter.set_size.remote(sum(m[2] for m in sizes)))
    kept = []
    if shm:  # segments on this node die with this process, whatever kills it (its resource tracker)
        here = node_id()
        kept = [i["name"] for i in get([s.shm_info.remote() for s in shards]) if i and i["node"] == here]
        for name in kept:
            keep_with_process(name)
    return ReplayClient(cfg, fields, shards, limiter, server, url, pwfile, namespaces, kept)


def _named(role, section: ReplayConfig, i: int, args: tuple) -> NamedHandle:
    """Actor i of a replay role, with its table entry's resources and options, under a name: the
    client goes into restartable actors' constructors, where a name crosses and a handle would not
    (`runtime/named.py`)."""
    import ray

    opts = dict(role.resources(section).options(), max_restarts=role.max_restarts(None), **role.options)
    return start_named(ray.remote(role.actor()), role.name, i, args, **opts)
