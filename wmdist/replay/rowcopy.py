"""RowSource: rows copied out of several shards' arrays by address, in one compiled call.

A client's gather reads each drawn row from its shard's shared-memory segment. numpy's take
costs a call per array and shard and writes rows only to consecutive places, so a batch whose
rows come from the shards in any order (a stock shuffled over the shards: `stock.py`) would
need a second copy, or one pass per shard over the batch, which measured 15-25% slower with
caches cold (the batch written in interleaved passes). This copies the rows of every array
of every shard in one call, in the batch's order (its writes sequential, each row one
memcpy, as numpy's take does per row), from a table of the arrays' base addresses built
once per mapping.
"""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def _memcpy(typingctx, dst, src, nbytes):
    """memcpy(dst, src, nbytes) on raw addresses (LLVM's memcpy: libc's for large rows)."""
    def codegen(context, builder, signature, args):
        d, s, n = args
        cgutils.raw_memcpy(builder, builder.inttoptr(d, cgutils.voidptr_t), builder.inttoptr(s, cgutils.voidptr_t),
                           n, 1)
        return context.get_dummy_value()

    return types.none(types.int64, types.int64, types.int64), codegen


@njit(cache=True, nogil=True)
def _copy(src: np.ndarray, row_bytes: np.ndarray, shard_of: np.ndarray, rows: np.ndarray, dst: np.ndarray,
          at: np.ndarray) -> None:
    # src [S, P] base addresses (array p of shard s), row_bytes [P], dst [P] base addresses;
    # shard_of, rows, at [n]: row rows[i] of shard shard_of[i] goes to row at[i] (all checked
    # to be in range by RowSource.copy, whose caller keeps the arrays alive)
    for p in range(row_bytes.size):
        rb, d = row_bytes[p], dst[p]
        for i in range(rows.size):
            _memcpy(d + at[i] * rb, src[shard_of[i], p] + rows[i] * rb, rb)


class RowSource:
    """P arrays per shard ([S][P]; the same row shape and dtype for every shard) to copy rows from."""

    def __init__(self, arrays: list[list[np.ndarray]]) -> None:
        if not arrays or any(len(a) != len(arrays[0]) for a in arrays):
            raise ValueError("every shard needs the same arrays")
        for shard in arrays:
            for a, ref in zip(shard, arrays[0]):
                if not a.flags.c_contiguous or a.shape[1:] != ref.shape[1:] or a.dtype != ref.dtype:
                    raise ValueError("row sources must be C-contiguous with the same row shape and dtype per shard")
        self._arrays = arrays  # kept alive while their addresses are in use
        self.tab = np.array([[a.ctypes.data for a in shard] for shard in arrays], np.int64)  # [S, P]
        self.rows = [(a.shape[1:], a.dtype) for a in arrays[0]]
        self.row_bytes = np.array([a.dtype.itemsize * int(np.prod(a.shape[1:], dtype=np.int64)) for a in arrays[0]],
                                  np.int64)
        self.capacity = min(a.shape[0] for shard in arrays for a in shard)

    def copy(self, shard_of: np.ndarray, rows: np.ndarray, dsts: list[np.ndarray],
             at: np.ndarray | None = None) -> None:
        """dsts[p][at[i]] = arrays[shard_of[i]][p][rows[i]] for every array p and i < n (`at`
        defaults to 0..n-1); every index is checked to be in range first."""
        shard_of = np.ascontiguousarray(shard_of, np.int64)
        rows = np.ascontiguousarray(rows, np.int64)
        n = rows.size
        at = np.arange(n, dtype=np.int64) if at is None else np.ascontiguousarray(at, np.int64)
        if shard_of.shape != (n,) or at.shape != (n,) or rows.ndim != 1:
            raise ValueError("shard_of, rows and at must be 1-D of the same length")
        if len(dsts) != len(self.rows):
            raise ValueError(f"{len(self.rows)} destination arrays needed, {len(dsts)} given")
        for d, (shape, dtype) in zip(dsts, self.rows):
            if not d.flags.c_contiguous or d.shape[1:] != shape or d.dtype != dtype:
                raise ValueError(f"a destination of rows {dtype}{shape} is {d.dtype}{d.shape[1:]} or not contiguous")
        if n == 0:
            return
        if (shard_of.min() < 0 or shard_of.max() >= len(self.tab) or rows.min() < 0 or rows.max() >= self.capacity
                or at.min() < 0 or at.max() >= min(d.shape[0] for d in dsts)):
            raise IndexError("row index out of range")
        _copy(self.tab, self.row_bytes, shard_of, rows, np.array([d.ctypes.data for d in dsts], np.int64), at)
