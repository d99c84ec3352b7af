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

import numpy as np
import ray
from ray.exceptions import RayActorError, RayTaskError

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import Sample, SequenceBatch, make_keys, split_keys
from wmdist.replay.config import ReplayConfig
from wmdist.replay.shard import DROP_REASONS
from wmdist.replay.storage_redis import (RecordsMissing, connect, encode_rows, fetch_records, new_keys,
                                         put_records)
from wmdist.runtime.replay_actor import LimiterActor, ShardActor


def route(source_id: int, episode_id: np.ndarray, shards: int) -> np.ndarray:
    """Shard of each episode: a 64-bit mix of (collector id, episode id) modulo S."""
    with np.errstate(over="ignore"):
        h = np.uint64(source_id) * np.uint64(0x9E3779B97F4A7C15) ^ episode_id.astype(np.uint64)
        h = (h ^ (h >> np.uint64(31))) * np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    return (h % np.uint64(shards)).astype(np.int64)


class ReplayClient:
    def __init__(self, cfg: ReplayConfig, fields: dict[str, FieldSpec], shards: list, limiter, server=None,
                 redis_url: str = "", password_file: str = "", namespaces: list[str] | None = None) -> None:
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

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.update(_server=None, _owner=False, _rng=None, _redis=None, _warm=False)
        return state

    @property
    def direct(self) -> bool:
        """Redis backend: this client moves record bytes to and from redis itself."""
        return self.cfg.backend == "redis"

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
        try:
            if self.cfg.samples_per_insert == 0 and lag == 0:  # never waits: count it without a round trip
                self.limiter.acquire_insert.remote(n, 0)
                ok, version = True, -1
            else:
                ok, version = ray.get(self.limiter.acquire_insert.remote(n, timeout))
        except RayActorError:
            return False  # the service was shut down
        if not ok:
            return False
        min_version = version - lag if lag > 0 and version >= 0 else None
        dest = route(source_id, batch.episode_id, len(self.shards))
        if self.direct:
            steps = self._insert_direct(batch, dest, min_version)
        else:  # one batched call per shard; Ray carries the arrays
            targets = np.unique(dest)
            steps = sum(ray.get([self.shards[s].insert.remote(
                batch if targets.size == 1 else batch.select(np.flatnonzero(dest == s)), min_version)
                for s in targets]))
        self.limiter.commit_insert.remote(steps)
        return True

    def _insert_direct(self, batch: SequenceBatch, dest: np.ndarray, min_version: int | None) -> int:
        """Records go to redis in one pipeline, then each shard indexes its keys (one small
        call). A shard that restarted in between has removed the records as unacknowledged
        and refuses them: they are written again for that shard only."""
        keep = np.ones(len(batch), bool) if min_version is None else batch.version >= min_version
        steps = batch.mask.sum(axis=1).astype(np.int64)
        plan = {int(s): (np.flatnonzero((dest == s) & keep), int(((dest == s) & ~keep).sum()))
                for s in np.unique(dest)}
        todo, stored = list(plan), 0
        for attempt in range(3):
            records, refs = {}, {}
            for s in todo:
                rows, lag = plan[s]
                keys = new_keys(self._namespaces[s], rows.size)
                records.update(zip(keys, encode_rows(batch, rows)))
                refs[s] = (keys, rows, lag)
            put_records(self.redis, records)
            refs = {s: self.shards[s].insert_keys.remote(keys, batch.version[rows], batch.episode_id[rows],
                                                         steps[rows], lag)
                    for s, (keys, rows, lag) in refs.items()}
            todo = []
            for s, ref in refs.items():
                try:
                    stored += ray.get(ref)
                except RayTaskError as e:
                    if attempt == 2 or not isinstance(e.cause, RecordsMissing):
                        raise
                    todo.append(s)
            if not todo:
                break
        return stored

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
                self.limiter.acquire_sample.remote(batch_size, 0)
            elif limited:
                if not ray.get(self.limiter.acquire_sample.remote(batch_size, timeout)):
                    return None
                self._warm = self.cfg.samples_per_insert == 0
            if not limited and sum(m[0] for m in ray.get([s.mass.remote() for s in self.shards])) == 0:
                return None
        except RayActorError:
            return None
        try:
            return self._sample(batch_size)
        except RayActorError:
            return None  # the service was shut down

    def _sample(self, batch_size: int) -> Sample:
        S = len(self.shards)
        if S == 1:
            counts, n, mass = np.array([batch_size]), 0, 0.0
        else:  # split B by size (uniform) or priority mass (prioritized) so shards act as one buffer
            masses = ray.get([s.mass.remote() for s in self.shards])
            n = sum(m[0] for m in masses)
            mass = sum(m[1] for m in masses)
            if mass <= 0:
                raise ValueError("replay is empty (min_size 0 and nothing inserted)")
            counts = self.rng.multinomial(batch_size, np.array([m[1] for m in masses]) / mass)
        beta = self.cfg.priority_beta if self.cfg.sampler == "prioritized" else 0.0
        fetch = not self.direct
        parts = [(i, self.shards[i].sample.remote(int(k), beta, n, mass, fetch)) for i, k in enumerate(counts) if k > 0]
        got = ray.get([r for _, r in parts])
        w = np.concatenate([g["is_weight"] for g in got])
        shard_of = np.concatenate([np.full(len(g["slots"]), i) for (i, _), g in zip(parts, got)])
        slots = np.concatenate([g["slots"] for g in got])
        stamps = np.concatenate([g["stamps"] for g in got])
        if fetch:
            data = {f: np.concatenate([g["data"][f] for g in got]) for f in self.fields}
            mask = np.concatenate([g["mask"] for g in got])
        else:
            keys = [k for g in got for k in g["keys"]]
            data, mask = self._fetch_direct(keys, shard_of, slots, stamps, w, beta, n, mass)
        return Sample(
            data=data,
            mask=mask.astype(np.float32),
            is_weight=(w / w.max()).astype(np.float32),  # normalised by the batch max (Schaul et al. 2016)
            keys=make_keys(shard_of, slots),
            stamps=stamps,
        )

    def _fetch_direct(self, keys, shard_of, slots, stamps, w, beta, n, mass):
        """One MGET of the drawn records. Rows whose record is gone or undecodable are reported
        to their shard (which drops and counts them unless the slot was rewritten since the
        draw, i.e. evicted) and drawn again from the same shard."""
        data, mask, missing, corrupt = fetch_records(self.redis, keys, self.fields, self.cfg.seq_len)
        redo = np.union1d(missing, corrupt)
        for _ in range(100):
            if redo.size == 0:
                return data, mask
            by_shard = [(s, redo[shard_of[redo] == s]) for s in np.unique(shard_of[redo])]
            ray.get([self.shards[s].drop_corrupt.remote(slots[rows], stamps[rows]) for s, rows in by_shard])
            again = []
            for s, rows in by_shard:
                g = ray.get(self.shards[s].sample.remote(rows.size, beta, n, mass, False))
                d2, m2, miss2, corr2 = fetch_records(self.redis, g["keys"], self.fields, self.cfg.seq_len)
                for f in self.fields:
                    data[f][rows] = d2[f]
                mask[rows] = m2
                slots[rows], stamps[rows], w[rows] = g["slots"], g["stamps"], g["is_weight"]
                again.append(rows[np.union1d(miss2, corr2)])
            redo = np.concatenate(again)
        raise RuntimeError("replay: could not read a batch from redis after 100 redraws")

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
        return int(sum(ray.get(refs)))

    def write_back(self, keys: np.ndarray, stamps: np.ndarray, fields: dict[str, np.ndarray]) -> int:
        """Overwrite stored fields [B, T, ...] of sampled keys; stale rows are dropped and counted."""
        refs = [self.shards[s].write_back.remote(sl, st, {k: v[rows] for k, v in fields.items()})
                for s, rows, sl, st in self._by_shard(keys, stamps)]
        return int(sum(ray.get(refs)))

    def set_policy_version(self, version: int) -> None:
        """The learner's latest published version (drives `max_policy_lag`)."""
        self.limiter.set_version.remote(int(version))

    # -- stats, checkpoints, shutdown ---------------------------------------------------
    def stats(self) -> dict[str, float]:
        per = ray.get([s.stats.remote() for s in self.shards])
        out: dict[str, float] = {}
        for i, st in enumerate(per):
            for k, v in st.items():
                out[f"shard{i}_{k}"] = v
                out[k] = out.get(k, 0.0) + v
        for r in DROP_REASONS:
            out.setdefault(f"drops_{r}", 0.0)
        out.update(ray.get(self.limiter.stats.remote()))
        return out

    def save(self, directory: str) -> None:
        """Shards write `shard<i>.npz` (memory: all data; redis: index only), plus limiter state."""
        os.makedirs(directory, exist_ok=True)
        ray.get([s.save.remote(os.path.join(os.path.abspath(directory), f"shard{i}.npz"))
                 for i, s in enumerate(self.shards)])
        state = ray.get(self.limiter.state_dict.remote())
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
        ray.get([s.restore.remote(os.path.join(os.path.abspath(directory), f"shard{i}.npz"))
                 for i, s in enumerate(self.shards)])
        ray.get(self.limiter.load_state_dict.remote(state))

    def close(self) -> None:
        """Owner: wake every waiter of the service (they return False/None), then stop the
        actors and the private redis-server. A pickled copy only stops using the service."""
        if self._closed:
            return
        self._closed = True
        if self._redis is not None:
            self._redis.close()
        if not self._owner:
            return
        try:
            ray.get(self.limiter.close.remote(), timeout=30)
        except Exception:  # already gone: nothing left to wake
            pass
        try:
            ray.get([s.close.remote() for s in self.shards], timeout=30)
        except Exception:
            pass
        for a in [*self.shards, self.limiter]:
            ray.kill(a, no_restart=True)
        if self._server is not None:
            self._server.stop()
            self._server = None


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


def create_replay(cfg: ReplayConfig, fields: dict[str, FieldSpec], run_dir: str, run_name: str) -> ReplayClient:
    """Start the shard actors, the limiter and (redis with no URL) a private redis-server."""
    cfg.validate()
    if not ray.is_initialized():
        raise ValueError("create_replay needs Ray initialised first")
    cap = shard_capacity(cfg, fields)
    server, url, pwfile = None, "", ""
    if cfg.backend == "redis":
        if cfg.redis_url:
            url, pwfile = cfg.redis_url, cfg.redis_password_file
        else:
            from wmdist.replay.redis_server import RedisServer

            server = RedisServer(os.path.join(run_dir, "redis"), cfg.redis_appendfsync, cfg.redis_aof).start()
            url, pwfile = server.url, server.password_file
    namespaces = [f"wmdist:{run_name}:s{i}" for i in range(cfg.shards)]
    shard_cls = ray.remote(ShardActor).options(num_cpus=cfg.shard_cpus, max_concurrency=8, max_restarts=-1,
                                               max_task_retries=3)
    shards = [shard_cls.remote(fields, cfg.seq_len, cap, cfg.sampler, cfg.priority_alpha, i, cfg.seed + i,
                               cfg.backend, url, pwfile, namespaces[i]) for i in range(cfg.shards)]
    limiter = ray.remote(LimiterActor).options(num_cpus=0, max_concurrency=64).remote(
        cfg.samples_per_insert, cfg.min_size, cfg.error_buffer)
    try:
        sizes = ray.get([s.mass.remote() for s in shards])  # also waits for redis shards to rebuild
    except Exception:
        if server is not None:
            server.stop()
        raise
    ray.get(limiter.set_size.remote(sum(m[2] for m in sizes)))
    return ReplayClient(cfg, fields, shards, limiter, server, url, pwfile, namespaces)
