"""Memory layout of the batched search trees (shared by the numba kernels and the engine).

The B trees live in preallocated arrays indexed [b, node]; node 0 is the root and the
leaf created at simulation s is node s + 1.

Array layout (N = num_simulations + 1 nodes, A actions):
    nodes_f  [B, N, 4] float64  VALUE_SUM, REWARD (edge reward into the node), RAW_VALUE
                                (network value), PREFIX (value prefix, EfficientZero)
    nodes_i  [B, N, 5] int32    VISITS (incl. own expansion), PARENT, DEPTH, ACTION (edge from
                                parent), HAS_PRIOR (PRIOR row computed: done lazily, the first
                                time pUCT selects at the node, as most leaves never get there)
    children [B, N, A] int32    child node index, -1 if unexpanded
    edges_f  [B, N, 4, A] float64  PRIOR (pUCT prior, noised at the root), LOGIT, Q (of the
                                edge, parent's view; valid once visited), N (child visits)
                                -- Q and N mirror the child's node so selection reads one
                                contiguous row per node instead of chasing child indices
    legal    [B, A] bool        root legal mask
    gumbel   [B, A] float64     root Gumbel noise (zeros in pUCT mode)
    minmax   [B, 2] float64     running min / max of the Q values in each tree
    table    [M + 1, S] int32   sequential-halving schedule (noise.considered_visit_table)
    params   [NUM_PARAMS] float64  see P_* below
    sel      [3, B] int64       the pending leaf of each row: parent node, action, reset flag
    store    [B, N, W] uint64   every node's latent as raw 8-byte words (latents.LatentStore);
    staged, gathered [B, W]     the incoming leaves' latents / the pending parents' latents
"""
from __future__ import annotations

VALUE_SUM, REWARD, RAW_VALUE, PREFIX = 0, 1, 2, 3
VISITS, PARENT, DEPTH, ACTION, HAS_PRIOR = 0, 1, 2, 3, 4
PRIOR, LOGIT, EDGE_Q, EDGE_N = 0, 1, 2, 3
SEL_PARENT, SEL_ACTION, SEL_RESET = 0, 1, 2

# params vector (floats; flags are 0.0 / 1.0)
P_C1, P_C2, P_GAMMA_SIGN, P_UNVISITED_PARENT, P_GUMBEL, P_C_VISIT, P_C_SCALE = 0, 1, 2, 3, 4, 5, 6
P_VALUE_PREFIX, P_HORIZON, P_MAX_CONSIDERED, P_NOISE_FRACTION = 7, 8, 9, 10
NUM_PARAMS = 11

RESCALE_EPS = 1e-8  # floor of the min-max range when rescaling completed Q (Gumbel)

# Kernel status codes (the Python side turns them into ValueErrors).
OK, NON_FINITE = 0, 1
