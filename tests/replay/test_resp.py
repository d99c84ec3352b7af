"""The replay's own request packing (`replay/resp.py`) against redis-py's packer as the
reference, and its pipeline against a real redis-server: replies in order, an error reply
raised without leaving stale replies on a pooled connection, a killed connection replaced."""
from __future__ import annotations

import pytest
import redis
from redis.connection import PythonRespSerializer

from wmdist.replay import resp
from wmdist.replay.storage_redis import connect


def _reference(commands, chunk: int) -> bytes:  # redis-py's packing, argument by argument
    ser = PythonRespSerializer(chunk, redis.connection.Encoder("utf-8", "strict", False).encode)
    return b"".join(bytes(p) for cmd in commands for p in ser.pack(*cmd))


CASES = [
    [(b"SET", b"k", b"v")],
    [(b"MSET", *[x for i in range(40) for x in (f"key:{i}", bytes([i]) * (100 * i))])],
    [(b"SET", "big", b"x" * 70_000), (b"GET", "big"), ("EVAL", b"return 1", 0)],
    [(b"SET", "empty", b""), (b"RPUSH", "l", 7, -3, memoryview(b"abc")), (b"DEL", "l")],
    [(b"SET", f"k{i}", b"y" * 5_000) for i in range(30)],
]


@pytest.mark.parametrize("commands", CASES)
@pytest.mark.parametrize("chunk", [16, 4096, 64 << 10])
def test_pack_gives_redis_pys_bytes_in_bounded_writes(commands, chunk):
    chunks = resp.pack(commands, chunk)
    assert b"".join(bytes(c) for c in chunks) == _reference(commands, chunk)
    args = [a for cmd in commands for a in cmd]
    big = [a for a in args if isinstance(a, (bytes, memoryview)) and len(a) > chunk]
    for c in chunks:  # a joined write passes `chunk` by at most one argument and its framing
        assert len(c) <= chunk + max((len(a) for a in args if not isinstance(a, int)), default=0) + 32 \
            or any(c is a for a in big)
    for a in big:  # a large argument goes out as it is, not copied into a joined write
        assert any(c is a for c in chunks)


def test_pack_refuses_what_redis_cannot_take():
    with pytest.raises(TypeError, match="float"):
        resp.pack([(b"SET", "k", 1.5)])
    with pytest.raises(ValueError, match="empty"):
        resp.pack([()])


def test_execute_against_a_real_server(redis_server):
    c = connect(redis_server.url, redis_server.password_file)
    recs = {f"wmdist:test:resp:{i}".encode(): bytes([i]) * 7_000 for i in range(32)}
    replies = resp.execute(c, [(b"MSET", *[x for kv in recs.items() for x in kv]),
                               (b"EVAL", b"return #KEYS", len(recs), *recs), (b"GET", next(iter(recs)))])
    assert replies[1:] == [32, next(iter(recs.values()))] and replies[0] in (b"OK", "OK", True)
    assert c.mget(list(recs)) == list(recs.values())
    # an error reply raises, and the replies after it are not left for the next caller to read
    with pytest.raises(redis.ResponseError):
        resp.execute(c, [(b"INCR", next(iter(recs))), (b"SET", b"wmdist:test:resp:after", b"1"), (b"PING",)])
    assert resp.execute(c, [(b"GET", b"wmdist:test:resp:after")]) == [b"1"]  # it ran; nothing stale read
    assert c.get(b"wmdist:test:resp:after") == b"1"
    # the server drops this client's connections: the next pipeline runs on a fresh one
    admin = connect(redis_server.url, redis_server.password_file)
    admin.execute_command("CLIENT", "KILL", "TYPE", "normal", "SKIPME", "yes")
    assert resp.execute(c, [(b"INCRBY", b"wmdist:test:resp:n", 2)]) == [2]
    c.delete(*recs, b"wmdist:test:resp:after", b"wmdist:test:resp:n")
