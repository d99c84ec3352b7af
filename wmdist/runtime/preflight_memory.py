"""Memory checks `wmdist train` makes before anything starts: a learner batch or a replay store
that cannot fit in this machine's memory is bad input (one line, exit 2), not an out-of-memory
kill minutes later that can take other runs on the node down with it.

The checks count raw stored bytes only, so they reject configs that can never fit and pass
every one that might: a batch is refused when its raw bytes pass a quarter of the memory (the
learner turns uint8 frames into float32, 4x), a replay store when its full capacity passes
the whole memory.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wmdist.config.errors import ConfigError

BATCH_SHARE = 0.25  # of memory: raw batch bytes above this cannot be held as float32 tensors


def node_memory_bytes() -> int | None:
    """Physical memory, or the cgroup's limit where it is lower; None if unknown."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return int(total)


def step_bytes(fields: dict) -> int:
    """Bytes of one stored step: every field, plus one byte of flags (as replay counts them)."""
    return 1 + sum(int(np.prod(s.shape)) * np.dtype(s.dtype).itemsize for s in fields.values())


def format_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} PiB"


def check_memory(cfg, fields: dict, memory: int | None = None) -> None:
    """Raise ConfigError if a learner or reanalyzer batch, or the replay store, cannot fit.

    `memory` defaults to this machine's; a run that joins a cluster (`ray.address`) is checked
    for its batches only, since its replay may live on another node."""
    memory = node_memory_bytes() if memory is None else memory
    if not memory:
        return
    per_step = step_bytes(fields)
    seq_len = cfg.replay.seq_len
    batches = [("learner.batch_size", cfg.learner.batch_size)]
    if cfg.reanalyze.num > 0:
        batches.append(("reanalyze.batch_size", cfg.reanalyze.batch_size))
    for name, size in batches:
        need = size * seq_len * per_step
        if need > BATCH_SHARE * memory:
            raise ConfigError(
                f"{name}: {size} windows of {seq_len} steps are {format_bytes(need)} of raw data per batch, more than "
                f"a quarter of this machine's memory ({format_bytes(memory)}); lower {name} or replay.seq_len")
    r = cfg.replay
    local_store = r.backend == "memory" or (r.backend == "redis" and not r.redis_url)
    if local_store and not cfg.ray.address:
        from wmdist.runtime.replay_client import shard_capacity

        try:
            steps = shard_capacity(r, fields) * r.shards * seq_len
        except ValueError:
            return  # too small, not too large: replay reports that itself
        need = steps * per_step
        if need > memory:
            raise ConfigError(
                f"replay.capacity_steps: {steps} stored steps of {format_bytes(per_step)} are {format_bytes(need)}, more than this "
                f"machine's memory ({format_bytes(memory)}); lower replay.capacity_steps or set replay.capacity_bytes")
