"""ReplayClient: what collectors, the learner and reanalyzers hold to use the replay service.

A small picklable object with the shard and limiter actor handles. Only the process that
called `create_replay` owns the service (its `close()` stops the actors and the private
redis-server); a pickled copy's `close()` only stops that copy.

Stats keys (`stats()`), all floats:
  `size_steps`, `size_sequences`, `capacity_sequences`, `inserts`, `samples`, `bytes` (memory
  backend: ring arrays + index; redis: index only) -- summed over shards;
  `drops_<reason>` summed, reason in stale_writeback, stale_priority, evicted, corrupt,
  policy_lag; the same keys per shard as `shard<i>_<key>`;
  limiter: `insert_wait_seconds`, `sample_wait_seconds`, `limiter_error` (S - I*spi),
  `limiter_inserted`, `limiter_sampled`, `limiter_size_steps` (steps ever stored),
  `policy_version`.
"""
from __future__ import annotations

import json
import os

import numpy as np
import ray
from ray.exceptions import RayActorError

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import Sample, SequenceBatch, make_keys, split_keys
from wmdist.replay.config import ReplayConfig
from wmdist.replay.shard import DROP_REASONS
from wmdist.runtime.replay_actor import LimiterActor, ShardActor


def route(source_id: int, episode_id: np.ndarray, shards: int) -> np.ndarray:
    """Shard of each episode: a 64-bit mix of (collector id, episode id) modulo S."""
    with np.errstate(over="ignore"):
        h = np.uint64(source_id) * np.uint64(0x9E3779B97F4A7C15) ^ episode_id.astype(np.uint64)
        h = (h ^ (h >> np.uint64(31))) * np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    return (h % np.uint64(shards)).astype(np.int64)


class ReplayClient:
    def __init__(self, cfg: ReplayConfig, fields: dict[str, FieldSpec], shards: list, limiter, server=None) -> None:
        self.cfg, self.fields = cfg, dict(fields)
        self.shards, self.limiter = list(shards), limiter
        self._server = server  # private redis-server (owner only)
        self._owner = True
        self._closed = False
        self._rng: np.random.Generator | None = None

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.update(_server=None, _owner=False, _rng=None)
        return state

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
        try:
            ok, version = ray.get(self.limiter.acquire_insert.remote(n, timeout))
        except RayActorError:
            return False  # the service was shut down
        if not ok:
            return False
        lag = self.cfg.max_policy_lag
        min_version = version - lag if lag > 0 and version >= 0 else None
        dest = route(source_id, batch.episode_id, len(self.shards))
        refs = [self.shards[s].insert.remote(batch.select(np.flatnonzero(dest == s)), min_version)
                for s in np.unique(dest)]  # one batched call per shard
        steps = sum(ray.get(refs))
        self.limiter.commit_insert.remote(steps)
        return True

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
            if limited and not ray.get(self.limiter.acquire_sample.remote(batch_size, timeout)):
                return None
            if not limited and sum(m[0] for m in ray.get([s.mass.remote() for s in self.shards])) == 0:
                return None
        except RayActorError:
            return None
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
        parts = [(i, self.shards[i].sample.remote(int(k), beta, n, mass)) for i, k in enumerate(counts) if k > 0]
        got = ray.get([r for _, r in parts])
        data = {f: np.concatenate([g["data"][f] for g in got]) for f in self.fields}
        w = np.concatenate([g["is_weight"] for g in got])
        keys = np.concatenate([make_keys(i, g["slots"]) for (i, _), g in zip(parts, got)])
        return Sample(
            data=data,
            mask=np.concatenate([g["mask"] for g in got]).astype(np.float32),
            is_weight=(w / w.max()).astype(np.float32),  # normalised by the batch max (Schaul et al. 2016)
            keys=keys,
            stamps=np.concatenate([g["stamps"] for g in got]),
        )

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
        """Wake every waiter (they return False/None); the owner also stops actors and redis."""
        if self._closed:
            return
        self._closed = True
        try:
            ray.get(self.limiter.close.remote(), timeout=30)
        except Exception:  # already gone: nothing left to wake
            pass
        if not self._owner:
            return
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
    shard_cls = ray.remote(ShardActor).options(num_cpus=cfg.shard_cpus, max_concurrency=8, max_restarts=-1,
                                               max_task_retries=3)
    shards = [shard_cls.remote(fields, cfg.seq_len, cap, cfg.sampler, cfg.priority_alpha, i, cfg.seed + i,
                               cfg.backend, url, pwfile, f"wmdist:{run_name}:s{i}") for i in range(cfg.shards)]
    limiter = ray.remote(LimiterActor).options(num_cpus=0, max_concurrency=64).remote(
        cfg.samples_per_insert, cfg.min_size, cfg.error_buffer)
    try:
        sizes = ray.get([s.mass.remote() for s in shards])  # also waits for redis shards to rebuild
    except Exception:
        if server is not None:
            server.stop()
        raise
    ray.get(limiter.set_size.remote(sum(m[2] for m in sizes)))
    return ReplayClient(cfg, fields, shards, limiter, server)
