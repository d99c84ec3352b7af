"""Memory layout of the batched search trees (shared by the numba kernels and the engine).

The B trees live in two flat buffers so that a kernel call unboxes two arrays instead of
a dozen (numba pays per array argument, and a B=1 search makes one call per simulation).
`unpack` (in `tree.py`) carves them into the named views below; it is the only place that
knows the offsets. Node 0 is the root and the leaf created at simulation s is node s + 1.

tree_f: float64 [F], in this order
    params   [P_SIZE]       see P_* below
    minmax   [B, 2]         running min / max of the Q values in each tree
    gumbel   [B, A]         root Gumbel noise (zeros in pUCT mode)
    scratch  [4, A]         per-row work rows of the selection rules
    nodes_f  [B, N, 4]      VALUE_SUM, REWARD (edge reward into the node), RAW_VALUE
                            (network value), PREFIX (value prefix, EfficientZero)
    edges_f  [B, N, 4, A]   PRIOR (pUCT prior, noised at the root), LOGIT, Q (of the edge,
                            parent's view; valid once visited), N (child visits) -- Q and N
                            mirror the child's node so selection reads one contiguous row
                            per node instead of chasing child indices
tree_i: int32 [I], in this order
    header   [H_SIZE]       B, N, A, M + 1, S (the dims every view is cut from)
    legal    [B, A]         root legal mask (0 / 1)
    table    [M + 1, S]     sequential-halving schedule (noise.considered_visit_table)
    nodes_i  [B, N, 5]      VISITS (incl. own expansion), PARENT, DEPTH, ACTION (edge from
                            parent), OPENED (1 once selection has passed through the node)
    children [B, N, A]      child node index, -1 if unexpanded

A node's nodes_f / nodes_i rows and LOGIT row are written when it is created
(`kernels._new_node`); its children, PRIOR, Q and N rows only when selection first passes
through it (`select.open_node`), which most leaves never see. So the buffers can be reused
from one search to the next without clearing (`workspace.py`), and a leaf costs a few
cache lines instead of ten.

Beside them: sel [3, B] int64, the pending leaf of each row (parent node, action, reset
flag; its action row is what recurrent_fn receives), and the latent buffers of
`latents.LatentStore`: store [B, N, W] uint64 (every node's latent as raw 8-byte words) and
io [2, B, W] uint64 (io[0] the incoming leaves' latents, io[1] the pending parents').
"""
from __future__ import annotations

VALUE_SUM, REWARD, RAW_VALUE, PREFIX = 0, 1, 2, 3
VISITS, PARENT, DEPTH, ACTION, OPENED = 0, 1, 2, 3, 4
PRIOR, LOGIT, EDGE_Q, EDGE_N = 0, 1, 2, 3
SEL_PARENT, SEL_ACTION, SEL_RESET = 0, 1, 2
STAGED, GATHERED = 0, 1  # rows of the latent io buffer

# params vector (floats; flags are 0.0 / 1.0)
P_C1, P_C2, P_GAMMA_SIGN, P_UNVISITED_PARENT, P_GUMBEL, P_C_VISIT, P_C_SCALE = 0, 1, 2, 3, 4, 5, 6
P_VALUE_PREFIX, P_HORIZON, P_MAX_CONSIDERED, P_NOISE_FRACTION = 7, 8, 9, 10
NUM_PARAMS = 11
P_SIZE = 16  # params slot in tree_f (keeps the arrays after it 16-float aligned)

# header of tree_i
H_BATCH, H_NODES, H_ACTIONS, H_TABLE_ROWS, H_TABLE_COLS = 0, 1, 2, 3, 4
H_SIZE = 8

RESCALE_EPS = 1e-8  # floor of the min-max range when rescaling completed Q (Gumbel)

# Kernel status codes (the Python side turns them into ValueErrors).
OK, NON_FINITE, BAD_SHAPE, NO_LEGAL = 0, 1, 2, 3
