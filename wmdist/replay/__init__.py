"""Sharded replay: storage, samplers, rate limiter and codec (no Ray here).

Pieces: `writer.SequenceWriter` (steps -> fixed windows, in collectors), `shard.ReplayShard`
(index + `sumtree.SumTree` sampler + storage), `storage_memory` / `storage_redis`,
`shard_shm.ShmShard` (a shard living in a `shm.ShmSegment`, with `storage_shm`,
`shm_rows`, `rowcopy`, `reservations`), `stock` (samples gathered ahead for a reader),
`limiter.RateLimiter`, `codec` (msgpack arrays, never pickle),
`redis_server` (private server launcher). The Ray actors and the client are
`wmdist/runtime/replay_{actor,client,shm}.py`.

Where the bytes go (a Ray actor call costs ~1-5 ms and copies what it carries):
- memory backend, shared memory (the default, `replay.shm`): each shard keeps its ring
  arrays `[C, T, ...]`, mask, per-slot index and counters in one POSIX shared-memory
  segment (`shard_shm.py`); processes on its node map it. An insert writes the rows into
  slots the client reserved ahead (a reservation takes the slot's old row out of the index),
  then commits them in the segment (commit record, then the slot's write id): acknowledged
  then, with no shard call on the path while the stock of reserved slots lasts (the next
  ones are asked for ahead, not waited for). The shard indexes committed slots on its next
  read; a shard killed and restarted by Ray re-attaches the segment and indexes them too,
  so it loses no acknowledged sequence. Uncommitted reservations (a killed collector) are
  holes, never indexed. A sample takes draws from the same pools as redis (below), then
  copies the rows itself from the mapped segments (`rowcopy.RowSource`: every array of
  every shard in one compiled call, rows in the batch's order), checking each slot's stamp
  and generation before and after the copy (a seqlock: a row rewritten meanwhile is drawn
  again, counted as `stale_reads`).
- memory backend through actor calls (`replay.shm` off, a client on another node than the
  shard, or no shared memory there): a collector's complete windows travel as one
  `SequenceBatch` in one batched actor call per destination shard (Ray's object store
  carries the numpy buffers); the shard copies them once into its ring arrays. A sample is
  one call per shard returning the gathered rows `[k, T, ...]`.
- redis backend: bytes never go through Ray, and neither a shard nor any Ray call sits on
  the insert path or (most of the time) the sample path. An insert is one pipeline from the
  client, no transaction: the records (msgpack, encoded through a precomputed
  `layout.RecordLayout`; one SET each when big, so redis runs them while the rest is still
  on the wire), then per destination shard a small script that pushes one entry on that
  shard's pending list if all its records are there (`storage_redis.commit_records`). It is
  acknowledged when redis answers (after fsync under `appendfsync always`); records whose
  entry never got pushed (a crash in between) are deleted by the shard's next load, never
  indexed. Shards index pending entries
  on their next read and on a 0.2 s tick (index + LTRIM in one transaction, so exactly once;
  a restarted shard indexes them too). A sample takes (slot, stamp, key, mass) draws from
  per-shard pools (`draws.DrawPools`): each shard is asked for ~16 samples' worth at a time,
  16 samples before they are needed, so a shard call is on the sample's path only when a
  pool runs short (and then it is that request, back long since). Then one MGET of the
  records, decoded for the whole batch (`layout.RecordLayout.decode_many`). A client's own
  insert or write-back voids its pools (read your writes); draws are at most a second old
  (counted from the request); a pooled draw whose record was evicted since is drawn again.
- Both drawn paths (shared memory, redis): a reader that samples back-to-back without
  writing gathers up to 32 batches at once (as many as its sample calls of the last 0.25 s,
  at most 8 MB) and serves the next samples as views of them (`stock.GatheredStock`); its
  next write or the draws' age limit ends the stock, and with several shards the stock's
  draws are shuffled so every batch served is an i.i.d. sample of the union.
- Both: an insert waits for the rate limiter only when the ratio or `max_policy_lag` is
  on, a sample only while the ratio is on or `min_size` is not reached yet; otherwise the
  counts gate nothing and are summed and sent without waiting at most every 50 ms
  (`coalesce.Coalescer`, on the caller's own thread: no timer thread calls into Ray), and
  always before a blocking limiter call; stats, a checkpoint, close and a copy's first
  count wait until the limiter applied them (a threaded actor may reorder calls). Memory by
  actor calls: one `mass` call per shard when S > 1 (the pools carry each shard's size and
  mass) to split B by size or priority mass. Write-backs go through the shard (stamp check,
  then a patch of the stored record, inside the slot's generation bracket in shared
  memory), one call per shard.
The shard actors are the only writers of their index, so stamp checks and eviction stay
consistent without redis-side locking; record keys are never reused, so a reader holding a
stale key gets the old record or nothing, never another sequence.
"""
