"""Memory layout of the batched search (shared by the numba kernels and the engine).

Everything a search keeps lives in one flat int64 buffer `mem`, so that a kernel call
unboxes one array instead of a dozen (numba pays per array argument, and a B=1 search
makes one call per simulation). The kernels read it through two views of the same
words, `f = mem.view(float64)` and `mem` itself for integers, and address it with flat
offsets: no array views are cut in the hot loops (each one costs numba two atomic
reference-count updates). `tree.Layout` holds the offsets; node 0 is the root and the
leaf created at simulation s is node s + 1.

mem, in this order (word offsets in `Layout`):
    header   [H_SIZE]        int: B, N, A, M + 1, S, W (the dims everything is cut from)
    params   [P_SIZE]        float: see P_* below
    pb_c     [S + 2]         float: pUCT exploration weight for parent visit counts 0..S+1
    minmax   [B, 2]          float: running min / max of the Q values in each tree
    gumbel   [B, A]          float: root Gumbel noise (zeros in pUCT mode)
    logits   [B, A]          float: root logits (the root's POLICY row may hold its prior)
    scratch  [4, A]          float: per-row work rows of the selection rules
    legal    [B, A]          int: root legal mask (0 / 1)
    table    [M + 1, S]      int: sequential-halving schedule (noise.considered_visit_table)
    sel      [3, B]          int: pending leaf per row (parent node, action, reset flag);
                             its action row is what recurrent_fn receives
    nodes    [B, N, K]       float: one block of K = NODE_HEADER + 4A words per node:
                             VALUE_SUM .. OPENED below, then four rows of A:
                             POLICY (logits; in pUCT mode the prior once the node is
                             opened), Q and N (of the edge, parent's view: they mirror the
                             child's node so selection reads one block instead of chasing
                             children), CHILD (child node index, -1 if unexpanded)
    store    [B, N, W]       latent of every node as raw 8-byte words (latents.LatentStore)
    io       [2, B, W]       io[STAGED]: the incoming leaves' latents, io[GATHERED]: the
                             pending parents' (the latents recurrent_fn receives)

A node's header and POLICY row are written when it is created (`kernels._expand`); its
Q, N and CHILD rows (and in pUCT mode its prior) only when selection first passes through
it (`select.open_node`), which most leaves never see. So the buffer is reused from one
search to the next without clearing (`workspace.py`), and a leaf costs a few cache lines.
Visit counts, parents and child indices are small integers held exactly in floats.
"""
from __future__ import annotations

# node block header (floats); the edge rows follow at NODE_HEADER + row * A
VALUE_SUM, REWARD, RAW_VALUE, PREFIX, VISITS, PARENT, ACTION, OPENED = 0, 1, 2, 3, 4, 5, 6, 7
NODE_HEADER = 8
POLICY, EDGE_Q, EDGE_N, CHILD = 0, 1, 2, 3  # edge rows of a node block
EDGE_ROWS = 4

SEL_PARENT, SEL_ACTION, SEL_RESET = 0, 1, 2
STAGED, GATHERED = 0, 1  # rows of the latent io region
SCRATCH_ROWS = 4

# params (floats; flags are 0.0 / 1.0)
P_C1, P_C2, P_GAMMA_SIGN, P_UNVISITED_PARENT, P_GUMBEL, P_C_VISIT, P_C_SCALE = 0, 1, 2, 3, 4, 5, 6
P_VALUE_PREFIX, P_HORIZON, P_MAX_CONSIDERED, P_NOISE_FRACTION = 7, 8, 9, 10
NUM_PARAMS = 11
P_SIZE = 16

# header (ints)
H_BATCH, H_NODES, H_ACTIONS, H_TABLE_ROWS, H_SIMS, H_WORDS = 0, 1, 2, 3, 4, 5
H_SIZE = 8

RESCALE_EPS = 1e-8  # floor of the min-max range when rescaling completed Q (Gumbel)

# Kernel status codes (the Python side turns them into ValueErrors).
OK, NON_FINITE, BAD_SHAPE, NO_LEGAL = 0, 1, 2, 3
