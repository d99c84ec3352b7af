"""Sharded replay: storage, samplers, rate limiter and codec (no Ray here).

Pieces: `writer.SequenceWriter` (steps -> fixed windows, in collectors), `shard.ReplayShard`
(index + `sumtree.SumTree` sampler + storage), `storage_memory` / `storage_redis`,
`limiter.RateLimiter`, `codec` (msgpack arrays, never pickle), `redis_server` (private
server launcher). The Ray actors and the client are `wmdist/runtime/replay_{actor,client}.py`.

Where the bytes go (a Ray actor call costs ~1-5 ms and copies what it carries):
- memory backend: a collector's complete windows travel as one `SequenceBatch` in one
  batched actor call per destination shard (Ray's object store carries the numpy buffers);
  the shard copies them once into its preallocated ring arrays. A sample is one call per
  shard returning the gathered rows `[k, T, ...]`.
- redis backend: bytes never go through Ray. The client encodes each window as one
  msgpack record and writes them in one pipeline straight to redis-server, then makes one
  small call per shard to index the keys (`insert_keys`, one MULTI/EXEC). A sample asks each
  shard for keys, stamps and weights only, then reads the records with one MGET.
- Both: one rate-limiter call per insert and per sample (none when the ratio is off and
  `min_size` is reached: the counts are sent without waiting), one `mass` call per shard
  when S > 1 (to split B by size or priority mass). Write-backs go through the shard
  (stamp check, then a patch of the stored record), one call per shard.
The shard actors are the only writers of their index, so stamp checks and eviction stay
consistent without redis-side locking; record keys are never reused, so a reader holding a
stale key gets the old record or nothing, never another sequence.
"""
