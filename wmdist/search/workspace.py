"""Reusable search buffers: the flat search buffer (`layout.py`) and its latent store.

Allocating and wiring them costs more than a whole B=1 search's tree work, and the
buffers of a large batch are megabytes of fresh pages, so each thread keeps the last few
workspaces by shape and reuses them. Reuse needs no clearing: a node's rows are written
when the node is created (`kernels._expand`). A workspace in use (a search started from
inside a recurrent_fn of the same thread) is never handed out twice.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmdist.search.latents import LatentStore, signature
from wmdist.search.tree import allocate, unpack

MAX_CACHED = 4  # workspaces kept per thread (least recently used dropped first)


@dataclass
class Workspace:
    mem: np.ndarray  # int64 flat search buffer (layout.py)
    params: np.ndarray  # [P_SIZE] float64 view of mem
    sel: np.ndarray  # [3, B] int64 view of mem: pending leaf per row (parent, action, reset)
    latents: LatentStore
    busy: bool = False

    def release(self) -> None:
        self.busy = False


_local = threading.local()


def _new(batch: int, num_actions: int, table: np.ndarray, root_latents: Any) -> Workspace:
    num_nodes = table.shape[1] + 1  # one node per simulation plus the root
    latents = LatentStore(root_latents, batch)
    mem = allocate(batch, num_nodes, num_actions, table, latents.words)
    views = unpack(mem)
    latents.bind(views["io"])
    latents.stage(root_latents)
    return Workspace(mem, views["params"], views["sel"], latents)


def acquire(batch: int, num_actions: int, table: np.ndarray, root_latents: Any) -> Workspace:
    """A workspace for B roots, A actions, the [M + 1, S] halving table (S = simulations)
    and latents shaped like `root_latents` (staged already). Call `release()` when done."""
    cache: dict | None = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = {}
    key = (batch, num_actions, table.shape, signature(root_latents))
    ws = cache.get(key)
    if ws is not None and ws.busy:  # re-entrant search: a private workspace, not cached
        ws = _new(batch, num_actions, table, root_latents)
    elif ws is None:
        ws = cache[key] = _new(batch, num_actions, table, root_latents)
        while len(cache) > MAX_CACHED:
            cache.pop(next(iter(cache)))  # least recently used
    else:
        cache[key] = cache.pop(key)  # most recently used last
        ws.latents.stage(root_latents)
    ws.busy = True
    return ws
