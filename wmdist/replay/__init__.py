"""Sharded replay: storage, samplers, rate limiter and codec (no Ray here).

Pieces: `writer.SequenceWriter` (steps -> fixed windows, in collectors), `shard.ReplayShard`
(index + `sumtree.SumTree` sampler + storage), `storage_memory` / `storage_redis`,
`limiter.RateLimiter`, `codec` (msgpack arrays, never pickle), `redis_server` (private
server launcher). The Ray actors and the client are `wmdist/runtime/replay_{actor,client}.py`.

Where the bytes go:
- insert: a collector's writer stacks its complete windows into one `SequenceBatch`; the
  client makes one limiter call, then one batched actor call per destination shard (Ray
  moves the numpy buffers through the object store; the shard copies them once into its
  ring arrays (memory) or encodes and writes them to redis in one MULTI/EXEC pipeline).
- sample: one limiter call, one `mass` call per shard when S > 1 (to split B by size or
  priority mass), one `sample` call per shard; the shard gathers rows from its ring arrays
  (memory) or fetches them with one pipelined HMGET round trip (redis).
- write-back: one call per shard carrying only keys, stamps and the new values.
The shard actors are the only writers of their redis namespace, so stamp checks and
eviction are consistent without redis-side locking.
"""
