"""Rows copied straight into and out of a shard's shared-memory segment (client side).

`read_rows` is a seqlock read: the slots' stamps and generations are read, the rows copied
(one compiled call for every array of every shard: `rowcopy.py`), then stamps and
generations read again. A row is good only
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
from wmdist.replay.rowcopy import RowSource
from wmdist.replay.shm import ShmSegment

_NONE = np.zeros(0, np.int64)


class ShmRows:
    """The row sources (`rowcopy.RowSource`) of a set of shard segments: their stamps and
    generations, and their fields (in `fields` order) and mask."""

    def __init__(self, segs: list[ShmSegment], fields: list[str]) -> None:
        self.fields = list(fields)
        self.meta = RowSource([[seg.meta["stamp"], seg.meta["gen"]] for seg in segs])
        self.data = RowSource([[seg.data[f] for f in self.fields] + [seg.mask] for seg in segs])


def read_rows(src: ShmRows, shard_of: np.ndarray, slots: np.ndarray, stamps: np.ndarray, out: dict[str, np.ndarray],
              mask_out: np.ndarray, on_copied: Callable[[], None] | None = None,
              at: np.ndarray | None = None) -> np.ndarray:
    """Copy rows `slots` [k] of shards `shard_of` [k] into `out[field]` [k, T, ...] and `mask_out`
    [k, T] (arrays of exactly k rows), or with `at` [k] into rows `at` of them (any length);
    returns the indices (into 0..k-1) of rows that changed since drawn with `stamps` [k].
    `on_copied` runs between the copy and the re-check (tests). The three copies are separate
    compiled calls, so the checks' loads are neither before nor after the copy in program order."""
    k = len(slots)
    s0, g0, s1, g1 = (np.empty(k, np.int64) for _ in range(4))
    src.meta.copy(shard_of, slots, [s0, g0])
    src.data.copy(shard_of, slots, [out[f] for f in src.fields] + [mask_out], at)
    if on_copied is not None:
        on_copied()
    src.meta.copy(shard_of, slots, [s1, g1])
    ok = (s0 == stamps) & (s1 == stamps) & (g1 == g0) & ((g0 & 1) == 0)
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
