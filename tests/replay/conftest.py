"""Replay test fixtures: a real redis-server (password, 127.0.0.1, free port), and replay
services on the session's real local Ray (`started`), closed after the test."""
from __future__ import annotations

import itertools

import pytest
import torch

from replay_helpers import FIELDS

from wmdist.replay.config import ReplayConfig
from wmdist.replay.redis_server import RedisServer

torch.set_num_threads(1)
_ns = itertools.count()



@pytest.fixture(scope="session")
def redis_server(tmp_path_factory):
    """One redis-server for the replay tests (AOF, appendfsync always); tests use fresh namespaces."""
    server = RedisServer(str(tmp_path_factory.mktemp("redis")), appendfsync="always").start()
    yield server
    server.stop()


@pytest.fixture
def namespace() -> str:
    return f"wmdist:test{next(_ns)}:s0"


@pytest.fixture(params=["memory", "redis"])
def backend(request) -> str:
    return request.param


@pytest.fixture
def make_shard(backend, request):
    """Factory of ReplayShard on the parametrised backend (redis: a fresh namespace per shard)."""
    from replay_helpers import FIELDS, T

    from wmdist.replay.shard import ReplayShard
    from wmdist.replay.storage_redis import RedisStorage

    def make(capacity: int = 64, sampler: str = "uniform", alpha: float = 1.0, seed: int = 0, namespace=None):
        storage = None
        if backend == "redis":
            server = request.getfixturevalue("redis_server")
            storage = RedisStorage(FIELDS, capacity, T, server.client(), namespace or f"wmdist:test{next(_ns)}:s0")
        return ReplayShard(FIELDS, T, capacity, sampler, alpha, storage, seed)

    return make


@pytest.fixture
def started(ray_session, tmp_path):
    """`start(cfg, name)` -> a replay service (shards, limiter, client) of FIELDS in tmp_path."""
    from wmdist.runtime.replay_client import ReplayClient, create_replay

    clients: list[ReplayClient] = []

    def start(cfg: ReplayConfig, name: str = "t") -> ReplayClient:
        c = create_replay(cfg, FIELDS, str(tmp_path), name)
        clients.append(c)
        return c

    yield start
    for c in clients:
        c.close()
