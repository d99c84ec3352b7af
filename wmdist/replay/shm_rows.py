"""Rows copied straight into and out of a shard's shared-memory segment (client side).

`read_rows` is a seqlock read: the slots' stamps and generations are read, the rows copied
(one numpy gather per array), then stamps and generations read again. A row is good only
if its stamp is still the one drawn and its generation did not move and is even: a row
evicted (stamp -1 from its reservation or the shard's write on), rewritten or written
back while it was being copied is reported, never returned as if it were the drawn one.
(Numpy copies are plain loads and stores; x86 keeps loads in order, and the shard's
writes reach its readers in program order, which is all the two checks need.)

`write_rows` fills slots this client reserved (out of the index until committed);
`commit_rows` then commits them: their commit records, then their write ids in `commit`,
after which the shard indexes them on its next read.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from wmdist.replay.batch import SequenceBatch
from wmdist.replay.shm import ShmSegment

_NONE = np.zeros(0, np.int64)


def read_rows(seg: ShmSegment, slots: np.ndarray, stamps: np.ndarray, out: dict[str, np.ndarray],
              mask_out: np.ndarray, on_copied: Callable[[], None] | None = None) -> np.ndarray:
    """Copy rows `slots` [k] into `out[field]` [k, T, ...] and `mask_out` [k, T] (contiguous
    arrays of exactly k rows); returns the indices (into 0..k-1) of rows that changed since
    drawn with `stamps` [k]. `on_copied` runs between the copy and the re-check (tests)."""
    stamp, gen, data = seg.meta["stamp"], seg.meta["gen"], seg.data
    s0, g0 = stamp.take(slots), gen.take(slots)  # [k] each (copies)
    for f, dst in out.items():
        data[f].take(slots, 0, dst, "clip")  # straight into dst; mode clip: no buffered copy
    seg.mask.take(slots, 0, mask_out, "clip")
    if on_copied is not None:
        on_copied()
    ok = (s0 == stamps) & (stamp.take(slots) == stamps) & (gen.take(slots) == g0) & ((g0 & 1) == 0)
    return _NONE if ok.all() else (~ok).nonzero()[0]


def write_rows(seg: ShmSegment, slots: np.ndarray, batch: SequenceBatch, rows: np.ndarray | None = None) -> None:
    """Rows `rows` of `batch` (all when None) into reserved `slots` [k]."""
    slots = np.asarray(slots, np.int64)
    at: slice | np.ndarray = slots
    if slots.size and slots[-1] - slots[0] == slots.size - 1 and np.all(np.diff(slots) == 1):
        at = slice(int(slots[0]), int(slots[-1]) + 1)  # the usual run of the ring: a plain block copy
    for f, src in batch.data.items():
        seg.data[f][at] = src if rows is None else src[rows]
    seg.mask[at] = batch.mask if rows is None else batch.mask[rows]


def commit_rows(seg: ShmSegment, slots: np.ndarray, stamps: np.ndarray, version: np.ndarray, episode: np.ndarray,
                steps: np.ndarray) -> None:
    """Commit written rows [k]: the shard indexes slot i once `commit[i]` is its write id,
    so that store comes last (the acknowledgement of the insert)."""
    m = seg.meta
    m["c_version"][slots], m["c_episode"][slots], m["c_steps"][slots] = version, episode, steps
    m["commit"][slots] = stamps
