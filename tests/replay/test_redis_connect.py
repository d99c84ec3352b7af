"""The replay's redis connections send in bulk: a pipeline of many records a few KB each goes out
in a few writes, not one per record (redis-py sends every argument above 6,000 bytes alone),
whatever the URL's connection class, and what is written reads back the same."""
from __future__ import annotations

import redis

from wmdist.replay.storage_redis import SEND_CHUNK, connect

RECORDS = [("SET", f"wmdist:test:bulk:{i}", bytes([i]) * 7000) for i in range(32)]


def test_pipelined_records_go_out_in_a_few_writes(redis_server):
    c = connect(redis_server.url, redis_server.password_file)
    conn = c.connection_pool.make_connection()
    plain = redis.Connection()
    assert len(plain.pack_commands(RECORDS)) >= 32  # redis-py alone: one write per record at least
    chunks = conn.pack_commands(RECORDS)
    assert len(chunks) <= 32 * 7100 // SEND_CHUNK + 2
    assert b"".join(map(bytes, chunks)) == b"".join(map(bytes, plain.pack_commands(RECORDS)))  # the same bytes
    p = c.pipeline(transaction=False)
    for _, k, v in RECORDS:
        p.set(k, v)
    p.execute()
    assert c.mget([k for _, k, _ in RECORDS]) == [v for _, _, v in RECORDS]
    c.delete(*[k for _, k, _ in RECORDS])


def test_every_url_scheme_keeps_its_connection_class():
    for url, base in (("redis://127.0.0.1:1/0", redis.Connection), ("rediss://127.0.0.1:1/0", redis.SSLConnection),
                      ("unix:///tmp/wmdist-none.sock", redis.UnixDomainSocketConnection)):
        cls = connect(url).connection_pool.connection_class
        assert issubclass(cls, base) and cls is not base
