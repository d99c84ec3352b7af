"""Ray actors of the replay service: thin wrappers that forward to `wmdist.replay`.

`ShardActor` holds one `ReplayShard` (threaded: a blocking call never stalls the others);
with the redis backend it rebuilds its index from redis in `__init__`, so a Ray restart
(`max_restarts`) after the process died brings back every acknowledged sequence. The
memory backend keeps everything in a shared-memory segment (`ShmShard`) when it can, which
a restarted actor re-attaches by name to the same effect; clients on its node read and
write rows there themselves (`shm_info`, `reserve`; see `wmdist/replay/shard_shm.py`).
Without shared memory (`replay.shm` off, or none on the node) rows live in the actor and
travel through its calls.
With redis the shard only indexes: clients write the record bytes and a pending entry
themselves and read them back by key (`draw`); a background thread drains the pending
entries every `DRAIN_SECONDS` (every read drains too), so eviction keeps up even while
nobody samples.
`LimiterActor` holds the one `RateLimiter` of the run (shared by all shards) and the
learner's current policy version (for `max_policy_lag`).
"""
from __future__ import annotations

import os
import threading

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch
from wmdist.replay.limiter import RateLimiter
from wmdist.replay.shard import ReplayShard
from wmdist.replay.shard_shm import ShmShard
from wmdist.replay.shm import ShmSegment, ShmUnavailable
from wmdist.replay.storage_memory import MemoryStorage

DRAIN_SECONDS = 0.2


class ShardActor:
    def __init__(self, fields: dict[str, FieldSpec], seq_len: int, capacity: int, sampler: str, alpha: float,
                 shard_id: int, seed: int, backend: str, redis_url: str = "", password_file: str = "",
                 namespace: str = "", shm_name: str = "", shm_token: int = 0) -> None:
        segment = None
        if backend == "memory" and shm_name:
            try:
                segment = ShmSegment.open(shm_name, fields, capacity, seq_len, shm_token)
            except (OSError, ShmUnavailable):
                segment = None  # no shared memory here: rows stay in this process
        if segment is not None:
            self.shard: ReplayShard = ShmShard(fields, seq_len, capacity, segment, sampler, alpha, seed, shard_id)
        else:
            if backend == "redis":
                from wmdist.replay.storage_redis import RedisStorage, connect

                storage = RedisStorage(fields, capacity, seq_len, connect(redis_url, password_file), namespace)
            else:
                storage = MemoryStorage(fields, capacity, seq_len)
            self.shard = ReplayShard(fields, seq_len, capacity, sampler, alpha, storage, seed, shard_id)
        self._stop = threading.Event()
        if backend == "redis":
            threading.Thread(target=self._drain_loop, name="drain", daemon=True).start()

    def _drain_loop(self) -> None:
        while not self._stop.wait(DRAIN_SECONDS):
            try:
                self.shard.drain()
            except Exception:  # noqa: BLE001 - redis away: entries stay pending, the next tick retries
                pass

    def pid(self) -> int:
        return os.getpid()

    def insert(self, batch: SequenceBatch, min_version: int | None) -> int:
        return self.shard.insert(batch, min_version)

    def draw(self, k: int, stale: int = 0) -> dict:
        return self.shard.draw(k, stale) if stale else self.shard.draw(k)

    def shm_info(self) -> dict | None:
        """{"name", "token", "capacity", "seq_len", "node"} of the shard's segment, or None."""
        if not isinstance(self.shard, ShmShard):
            return None
        import ray

        return {**self.shard.shm_info(), "node": ray.get_runtime_context().get_node_id()}

    def reserve(self, k: int) -> dict:
        return self.shard.reserve(k)

    def count_lag(self, n: int) -> None:
        self.shard.count_lag(n)

    def drop_corrupt(self, slots: np.ndarray, stamps: np.ndarray) -> int:
        return self.shard.drop_corrupt(slots, stamps)

    def mass(self) -> tuple[int, float, int]:
        return self.shard.mass()

    def sample(self, k: int, beta: float, global_count: int, global_mass: float) -> dict:
        return self.shard.sample(k, beta, global_count, global_mass)

    def update_priorities(self, slots: np.ndarray, stamps: np.ndarray, priorities: np.ndarray) -> int:
        return self.shard.update_priorities(slots, stamps, priorities)

    def write_back(self, slots: np.ndarray, stamps: np.ndarray, fields: dict[str, np.ndarray]) -> int:
        return self.shard.write_back(slots, stamps, fields)

    def stats(self) -> dict[str, float]:
        return self.shard.stats()

    def save(self, path: str) -> None:
        self.shard.save(path)

    def restore(self, path: str) -> None:
        self.shard.restore(path)

    def close(self) -> None:
        self._stop.set()
        with self.shard.lock:  # let a running drain finish before the connection closes
            self.shard.close()


class LimiterActor:
    def __init__(self, samples_per_insert: float, min_size: int, error_buffer: float) -> None:
        """A limiter Ray restarted after its process died reports `sized()` False until its
        owner gives it the shards' stored size again (`ReplayClient.resync_limiter`), so
        `min_size` does not hold the learner back again; its ratio counts start afresh (the
        band's slack absorbs that) and the policy version returns with the learner's next
        publish."""
        self.limiter = RateLimiter(samples_per_insert, min_size, error_buffer)
        self.version = -1  # latest learner policy version (-1 = none published yet)
        self._sized = False

    def acquire_insert(self, n: int, timeout: float | None) -> tuple[bool, int]:
        return self.limiter.acquire_insert(n, timeout), self.version

    def commit_insert(self, n_steps: int) -> None:
        self.limiter.commit_insert(n_steps)

    def record_insert(self, n: int, n_steps: int) -> None:
        """An insert that needed no permission (ratio off, no policy lag): count it and its steps."""
        self.limiter.acquire_insert(n, 0)
        self.limiter.commit_insert(n_steps)

    def acquire_sample(self, n: int, timeout: float | None) -> bool:
        return self.limiter.acquire_sample(n, timeout)

    def set_size(self, size_steps: int) -> None:
        self.limiter.set_size(size_steps)
        self._sized = True

    def sized(self) -> bool:
        return self._sized

    def set_version(self, version: int) -> None:
        self.version = max(self.version, int(version))

    def state_dict(self) -> dict:
        return {**self.limiter.state_dict(), "version": self.version}

    def load_state_dict(self, state: dict) -> None:
        self.limiter.load_state_dict(state)
        self.version = int(state.get("version", -1))
        self._sized = True

    def stats(self) -> dict[str, float]:
        return {**self.limiter.stats(), "policy_version": float(self.version)}

    def close(self) -> None:
        self.limiter.close()
