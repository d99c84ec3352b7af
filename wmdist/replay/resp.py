"""Requests to redis in the wire protocol (RESP), packed in one linear pass.

redis-py packs a pipeline by joining every argument onto a growing buffer until it passes its
cutoff. At the 64 KiB cutoff the replay's connections use (`storage_redis.SEND_CHUNK`), an
insert of 32 vector records copied ~1 MB to build ~200 KB: a third of the client's time on an
insert. `pack` collects the pieces in a list and joins each chunk once, so every byte is
copied once; an argument above the chunk size goes out as its own buffer, uncopied.
`execute` sends the chunks on one pooled connection and reads one reply per command.
"""
from __future__ import annotations

from collections.abc import Sequence

import redis
from redis.exceptions import ConnectionError as RedisConnectionError
from redis.exceptions import TimeoutError as RedisTimeoutError

Arg = bytes | bytearray | memoryview | str | int
CHUNK = 64 << 10  # bytes: pieces are joined into writes of about this size


def _as_bytes(a: Arg) -> bytes | bytearray | memoryview:
    if isinstance(a, (bytes, bytearray, memoryview)):
        return a
    if isinstance(a, str):
        return a.encode()
    if isinstance(a, int) and not isinstance(a, bool):
        return b"%d" % a
    raise TypeError(f"redis argument of type {type(a).__name__} (bytes, str or int expected)")


def pack(commands: Sequence[Sequence[Arg]], chunk: int = CHUNK) -> list[bytes | bytearray | memoryview]:
    """The request bytes of `commands` (each: name, then arguments), as writes of up to about
    `chunk` bytes; an argument larger than `chunk` is a write of its own."""
    out: list = []
    pieces: list = []
    size = 0
    for cmd in commands:
        if not cmd:
            raise ValueError("an empty redis command")
        pieces.append(b"*%d\r\n" % len(cmd))  # RESP: an array of bulk strings
        for a in cmd:
            if a.__class__ is not bytes:  # (most arguments are: skip the checks)
                a = _as_bytes(a)
            n = a.nbytes if isinstance(a, memoryview) else len(a)
            head = b"$%d\r\n" % n
            if n > chunk:  # sent as it is: joining would copy it for nothing
                pieces.append(head)
                out.append(b"".join(pieces))
                out.append(a)
                pieces, size = [b"\r\n"], 2
                continue
            pieces += (head, a, b"\r\n")
            size += n + len(head) + 2
            if size >= chunk:
                out.append(b"".join(pieces))
                pieces, size = [], 0
    if pieces:
        out.append(b"".join(pieces))
    return out


def execute(r: redis.Redis, commands: Sequence[Sequence[Arg]]) -> list:
    """Run `commands` as one pipeline (no transaction) on a connection of `r`'s pool -> their
    replies, as the parser gives them (no redis-py response callbacks). The first error reply
    raises. A send that fails on a dropped connection is sent again once on a fresh one
    (nothing of it ran, or only what the retry repeats: callers' commands must allow that);
    a failure while reading raises, since the commands may have run."""
    chunks = pack(commands)
    pool = r.connection_pool
    conn = pool.get_connection()
    try:
        try:
            conn.send_packed_command(chunks)
        except (RedisConnectionError, RedisTimeoutError):
            conn.disconnect()  # e.g. a pooled connection to a server that restarted since
            conn.send_packed_command(chunks)
        return [conn.read_response() for _ in commands]
    except BaseException:
        conn.disconnect()  # replies may be left unread on it: never reuse it
        raise
    finally:
        pool.release(conn)
