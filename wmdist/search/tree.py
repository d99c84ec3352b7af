"""The two flat tree buffers (see `layout.py`): their sizes, and `unpack` into named views."""
from __future__ import annotations

import numpy as np
from numba import njit

from wmdist.search.layout import H_ACTIONS, H_BATCH, H_NODES, H_SIZE, H_TABLE_COLS, H_TABLE_ROWS, P_SIZE


def buffer_sizes(batch: int, num_nodes: int, num_actions: int, table_shape: tuple[int, int]) -> tuple[int, int]:
    """(len(tree_f), len(tree_i)) for B trees of N nodes, A actions and an [M + 1, S] table."""
    b, n, a = batch, num_nodes, num_actions
    size_f = P_SIZE + b * 2 + b * a + 4 * a + b * n * 4 + b * n * 4 * a
    size_i = H_SIZE + b * a + table_shape[0] * table_shape[1] + b * n * 5 + b * n * a
    return size_f, size_i


def allocate(batch: int, num_nodes: int, num_actions: int, table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """New (tree_f, tree_i) with the header and the halving table filled in."""
    size_f, size_i = buffer_sizes(batch, num_nodes, num_actions, table.shape)
    tree_f = np.zeros(size_f)
    tree_i = np.zeros(size_i, dtype=np.int32)
    tree_i[[H_BATCH, H_NODES, H_ACTIONS, H_TABLE_ROWS, H_TABLE_COLS]] = (batch, num_nodes, num_actions) + table.shape
    table_view = unpack(tree_f, tree_i)[7]
    table_view[...] = table
    return tree_f, tree_i


@njit(cache=True)
def _view2(buf, offset, d0, d1):
    """C-ordered [d0, d1] view of buf[offset:] (a contiguous slice reshaped: no copy)."""
    return buf[offset:offset + d0 * d1].reshape((d0, d1))


@njit(cache=True)
def _view3(buf, offset, d0, d1, d2):
    return buf[offset:offset + d0 * d1 * d2].reshape((d0, d1, d2))


@njit(cache=True)
def _view4(buf, offset, d0, d1, d2, d3):
    return buf[offset:offset + d0 * d1 * d2 * d3].reshape((d0, d1, d2, d3))


@njit(cache=True)
def unpack(tree_f, tree_i):
    """Views (params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children)
    of the flat buffers (no copies); offsets in the order of `layout.py`, which
    `buffer_sizes` adds up."""
    b = np.int64(tree_i[H_BATCH])
    n = np.int64(tree_i[H_NODES])
    a = np.int64(tree_i[H_ACTIONS])
    rows = np.int64(tree_i[H_TABLE_ROWS])
    cols = np.int64(tree_i[H_TABLE_COLS])
    params = tree_f[:P_SIZE]
    o = P_SIZE
    minmax = _view2(tree_f, o, b, 2)
    o += b * 2
    gumbel = _view2(tree_f, o, b, a)
    o += b * a
    scratch = _view2(tree_f, o, 4, a)
    o += 4 * a
    nodes_f = _view3(tree_f, o, b, n, 4)
    o += b * n * 4
    edges_f = _view4(tree_f, o, b, n, 4, a)
    o = H_SIZE
    legal = _view2(tree_i, o, b, a)
    o += b * a
    table = _view2(tree_i, o, rows, cols)
    o += rows * cols
    nodes_i = _view3(tree_i, o, b, n, 5)
    o += b * n * 5
    children = _view3(tree_i, o, b, n, a)
    return params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children
