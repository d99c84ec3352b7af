"""The flat search buffer (see `layout.py`): its offsets (`Layout`), allocation and named views."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from wmdist.search.layout import (
    EDGE_ROWS,
    H_ACTIONS,
    H_BATCH,
    H_NODES,
    H_SIMS,
    H_SIZE,
    H_TABLE_ROWS,
    H_WORDS,
    NODE_HEADER,
    P_SIZE,
    SCRATCH_ROWS,
)


class Layout(NamedTuple):
    """Dims and word offsets of the regions of `mem` (numba passes it as a plain struct)."""

    batch: int  # B
    nodes: int  # N nodes per tree (simulations + 1)
    actions: int  # A
    block: int  # K words per node block
    sims: int  # S (columns of the halving table)
    table_rows: int  # M + 1
    words: int  # W latent words per node
    params: int
    pb_c: int
    minmax: int
    gumbel: int
    logits: int
    scratch: int
    legal: int
    table: int
    sel: int
    node0: int  # first node block
    store: int
    io: int
    size: int  # total words


@njit(cache=True)
def layout_for(batch, nodes, actions, table_rows, sims, words):
    """The Layout of a buffer for B trees of N nodes, A actions, an [M + 1, S] table and W
    latent words (regions in the order of `layout.py`; node blocks cache-line aligned)."""
    block = NODE_HEADER + EDGE_ROWS * actions
    params = H_SIZE
    pb_c = params + P_SIZE
    minmax = pb_c + sims + 2
    gumbel = minmax + batch * 2
    logits = gumbel + batch * actions
    scratch = logits + batch * actions
    legal = scratch + SCRATCH_ROWS * actions
    table = legal + batch * actions
    sel = table + table_rows * sims
    node0 = -(-(sel + 3 * batch) // 8) * 8  # a 64-byte boundary
    store = node0 + batch * nodes * block
    io = store + batch * nodes * words
    size = io + 2 * batch * words
    return Layout(batch, nodes, actions, block, sims, table_rows, words, params, pb_c, minmax, gumbel, logits,
                  scratch, legal, table, sel, node0, store, io, size)


@njit(cache=True)
def layout_of(mem):
    """The Layout of a buffer made by `allocate` (read from its header)."""
    return layout_for(mem[H_BATCH], mem[H_NODES], mem[H_ACTIONS], mem[H_TABLE_ROWS], mem[H_SIMS], mem[H_WORDS])


def allocate(batch: int, num_nodes: int, num_actions: int, table: np.ndarray, words: int) -> np.ndarray:
    """A new int64 buffer with the header and the halving table filled in."""
    rows, sims = table.shape
    lay = layout_for(batch, num_nodes, num_actions, rows, sims, words)
    mem = np.zeros(lay.size + 8, dtype=np.int64)
    start = (-mem.ctypes.data % 64) // 8  # node blocks on cache lines: align the buffer itself
    mem = mem[start:start + lay.size]
    mem[[H_BATCH, H_NODES, H_ACTIONS, H_TABLE_ROWS, H_SIMS, H_WORDS]] = (batch, num_nodes, num_actions, rows, sims,
                                                                          words)
    unpack(mem)["table"][...] = table
    return mem


def unpack(mem: np.ndarray) -> dict[str, np.ndarray]:
    """Named numpy views of the regions (no copies): float regions as float64, others int64."""
    lay = layout_of(mem)
    f = mem.view(np.float64)
    b, n, a, w = lay.batch, lay.nodes, lay.actions, lay.words

    def cut(buf: np.ndarray, start: int, *shape: int) -> np.ndarray:
        return buf[start:start + int(np.prod(shape))].reshape(shape)

    return {
        "params": cut(f, lay.params, P_SIZE), "pb_c": cut(f, lay.pb_c, lay.sims + 2),
        "minmax": cut(f, lay.minmax, b, 2), "gumbel": cut(f, lay.gumbel, b, a), "logits": cut(f, lay.logits, b, a),
        "scratch": cut(f, lay.scratch, SCRATCH_ROWS, a), "legal": cut(mem, lay.legal, b, a),
        "table": cut(mem, lay.table, lay.table_rows, lay.sims), "sel": cut(mem, lay.sel, 3, b),
        "nodes": cut(f, lay.node0, b, n, lay.block), "store": cut(mem, lay.store, b, n, w),
        "io": cut(mem, lay.io, 2, b, w),
    }
