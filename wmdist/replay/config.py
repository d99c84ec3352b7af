"""`ReplayConfig`: the `replay` section of the run config (see `wmdist/replay/__init__.py`)."""
from __future__ import annotations

from dataclasses import dataclass

from wmdist.config.fields import param


@dataclass
class ReplayConfig:
    backend: str = param(
        "memory", "where sequences are stored: in the shard processes or in redis-server", choices=("memory", "redis"))
    shm: bool = param(
        True, "memory backend: shards keep rows in shared memory, where collectors, learner and reanalyzers on "
              "their node write and read them without an actor call carrying the bytes (a killed shard re-attaches "
              "them); off, or for a process on another node, rows travel through actor calls")
    shards: int = param(1, "number of replay shard actors (episodes are hashed onto them)", ge=1, le=256)
    capacity_steps: int = param(
        1_000_000, "total stored steps over all shards (T per sequence slot); FIFO eviction", ge=1)
    capacity_bytes: int = param(0, "optional cap on stored array bytes over all shards (0 = none)", ge=0)
    seq_len: int = param(64, "steps T of one stored sequence", ge=1)
    overlap: int = param(0, "steps shared by consecutive windows of one episode (0..T-1)", ge=0)
    pack_episodes: bool = param(
        False, "an episode's end does not close its window: the env's next episode fills the rest, so every "
               "stored window holds seq_len real steps and samples_per_insert counts real steps (short "
               "episodes otherwise insert mostly padding). Only for learners that restart at `first` inside a "
               "window (Dreamer)")
    sampler: str = param("uniform", "how sequences are drawn", choices=("uniform", "prioritized"))
    priority_alpha: float = param(0.6, "priority exponent alpha: P(i) = p_i^alpha / sum p^alpha", ge=0)
    priority_beta: float = param(0.4, "importance-weight exponent beta: w_i = (N P(i))^-beta", ge=0, le=1)
    priority_beta_anneal_samples: int = param(
        0, "learner batches over which beta rises linearly from priority_beta to 1 (Schaul et al. 2016; "
           "EfficientZero: 0.4 -> 1); 0 = beta stays fixed", ge=0)
    samples_per_insert: float = param(
        0.0, "sampled sequences per inserted sequence (train ratio); 0 = no limiting", ge=0)
    min_size: int = param(1000, "stored steps (real, over all shards) before sampling starts", ge=0)
    error_buffer: float = param(
        1000.0, "slack of the rate limiter, in sampled sequences, around the target ratio", ge=0)
    redis_url: str = param(
        "", "redis://host:port/db of an external server ('' = a private redis-server in the run dir)")
    redis_password_file: str = param(
        "", "file holding the password of the external redis server ('' = none or in the URL)")
    redis_appendfsync: str = param(
        "everysec", "private redis-server AOF fsync policy", choices=("always", "everysec", "no"))
    redis_aof: bool = param(True, "private redis-server keeps an append-only file (durable across restarts)")
    sample_ahead: int = param(
        32, "most batches a reader that samples back-to-back without writing gathers at once and serves from "
            "memory (as many as its sample calls of the last 0.25 s, at most 8 MB; wmdist/replay/stock.py); 1 = every "
            "sample draws and reads its own rows", ge=1, le=256)
    shard_cpus: float = param(0.1, "Ray CPU share of each shard actor", gt=0)
    resources: dict = param(
        {}, "custom Ray resources of each shard actor and of the limiter, e.g. {replay: 1} to keep replay on the "
            "head node (deploy/ray/*.yaml give the head a `replay` resource)")
    max_policy_lag: int = param(
        0, "drop inserted sequences older than this many policy versions (0 = off)", ge=0)
    seed: int = param(0, "seed of the samplers (shard i uses seed + i)", ge=0)

    def validate(self) -> None:
        """Cross-field checks the per-field bounds can't express (one-line ValueError)."""
        if not 0 <= self.overlap < self.seq_len:
            raise ValueError(f"replay.overlap must be in [0, seq_len-1={self.seq_len - 1}], got {self.overlap}")
        if self.capacity_steps < self.seq_len * self.shards:
            raise ValueError(
                f"replay.capacity_steps={self.capacity_steps} holds less than one sequence per shard "
                f"(seq_len {self.seq_len} x shards {self.shards})"
            )
        if self.min_size > self.capacity_steps:  # a store that never holds min_size steps never lets sampling start
            raise ValueError(f"replay.min_size={self.min_size} exceeds replay.capacity_steps={self.capacity_steps}: "
                             f"the learner would wait forever for its first batch")
