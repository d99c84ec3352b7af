"""Selection rules of the batched search as numba helpers: pUCT (MuZero eq. 2) and Gumbel
MuZero (sequential halving at the root, deterministic interior selection, completed Q).

They read the flat buffer of `layout.py`: `f` is its float view, `mem` its int view, `lay`
its `tree.Layout`, and a node is addressed by `nb`, the offset of its block in `f`.
Flat indices are cast to unsigned (`U(...)`): numba then drops the negative-index
wraparound it adds to every signed index, which blocks vectorisation (the pUCT score loop
runs ~3x faster).
Floating-point operations are written in the same order as in `reference.py` so both give
bit-identical results (tests compare with ==). error_model="numpy" drops numba's
division-by-zero checks from the hot loops (inputs are checked finite, and no denominator
here can be 0: visit counts >= 1, spans floored).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from wmdist.search.layout import (
    CHILD,
    EDGE_N,
    EDGE_Q,
    NODE_HEADER,
    OPENED,
    P_C1,
    P_C2,
    P_C_SCALE,
    P_C_VISIT,
    P_GUMBEL,
    P_MAX_CONSIDERED,
    P_UNVISITED_PARENT,
    POLICY,
    RAW_VALUE,
    RESCALE_EPS,
    VALUE_SUM,
    VISITS,
)

U = np.uint64  # index cast: numba skips its negative-index wraparound for unsigned indices


@njit(cache=True, error_model="numpy")
def row(lay, nb, which):
    """Offset in f of edge row `which` (POLICY, EDGE_Q, EDGE_N, CHILD) of the node block at nb."""
    return nb + NODE_HEADER + which * lay.actions


@njit(cache=True, error_model="numpy")
def node_at(lay, b, node):
    """Offset in f of the block of node `node` of tree b."""
    return lay.node0 + (b * lay.nodes + node) * lay.block


@njit(cache=True, error_model="numpy")
def softmax_into(f, x, out, num, mem, mask, use_mask):
    """f[out:out+num] = softmax(f[x:x+num]) over the entries where mem[mask + a] != 0 (or
    all if not use_mask), others 0. out may equal x (each entry is read before written)."""
    mx = -np.inf
    for a in range(num):
        if (not use_mask or mem[U(mask + a)] != 0) and f[U(x + a)] > mx:
            mx = f[U(x + a)]
    total = 0.0
    for a in range(num):
        if not use_mask or mem[U(mask + a)] != 0:
            f[U(out + a)] = math.exp(f[U(x + a)] - mx)
            total += f[U(out + a)]
        else:
            f[U(out + a)] = 0.0
    for a in range(num):
        f[U(out + a)] = f[U(out + a)] / total


@njit(cache=True, error_model="numpy")
def pb_c_table(f, lay):
    """pb_c[n] = (c1 + log((n + c2 + 1) / c2)) * sqrt(n) for parent visits n = 0..S+1
    (MuZero eq. 2): the same operations as per selection step, done once per search."""
    c1 = f[U(lay.params + P_C1)]
    c2 = f[U(lay.params + P_C2)]
    for n in range(lay.sims + 2):
        parent_n = float(n)
        f[U(lay.pb_c + n)] = (c1 + math.log((parent_n + c2 + 1.0) / c2)) * math.sqrt(parent_n)


@njit(cache=True, error_model="numpy")
def normalize(q, lo, inv_span):
    """Tree min-max normalisation (MuZero appendix B), clipped to [0, 1]."""
    x = (q - lo) * inv_span
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@njit(cache=True, error_model="numpy")
def puct_select(f, mem, lay, b, nb, at_root):
    """argmax_a  Qnorm(s,a) + P(s,a) * pb_c(N(s)) / (1 + N(s,a)); the root mask applies at
    the root only; lowest index on ties. Scores go through the scratch row in a
    branch-free loop, then one argmax pass."""
    lo, hi = f[U(lay.minmax + 2 * b)], f[U(lay.minmax + 2 * b + 1)]
    inv_span = 1.0 / (hi - lo) if hi > lo else 0.0  # no range yet: every value score 0
    if inv_span == 0.0:
        lo = 0.0
    parent_n = f[U(nb + VISITS)]
    pb_c = f[U(lay.pb_c + int(parent_n))]
    if f[U(lay.params + P_UNVISITED_PARENT)] != 0.0:
        unvisited = normalize(f[U(nb + VALUE_SUM)] / parent_n, lo, inv_span)
    else:
        unvisited = 0.0
    num = lay.actions
    prior, edge_q, edge_n = row(lay, nb, POLICY), row(lay, nb, EDGE_Q), row(lay, nb, EDGE_N)
    scores = lay.scratch
    for a in range(num):
        visits = f[U(edge_n + a)]
        value_score = unvisited if visits == 0.0 else normalize(f[U(edge_q + a)], lo, inv_span)
        f[U(scores + a)] = value_score + f[U(prior + a)] * pb_c / (1.0 + visits)
    best = -np.inf
    best_a = -1
    legal = lay.legal + b * num
    for a in range(num):
        if f[U(scores + a)] > best and (not at_root or mem[U(legal + a)] != 0):
            best = f[U(scores + a)]
            best_a = a
    return best_a


@njit(cache=True, error_model="numpy")
def completed_sigma(f, mem, lay, b, nb, logits, at_root):
    """Gumbel MuZero completed Q at the node block nb with logits at f[logits:] (eq. 33
    mixed value for unvisited actions). Fills the scratch rows probs = softmax(logits),
    raw_q (completed Q) and sigma = (c_visit + max_b N(b)) * c_scale * rescaled completed
    Q (min-max over the node's actions, floor RESCALE_EPS). At the root only legal actions
    count (illegal raw_q = sigma = 0)."""
    num = lay.actions
    probs, raw_q, sigma = lay.scratch, lay.scratch + num, lay.scratch + 2 * num
    mask = lay.legal + b * num
    edge_q, edge_n = row(lay, nb, EDGE_Q), row(lay, nb, EDGE_N)
    softmax_into(f, logits, probs, num, mem, mask, at_root)
    sum_n = 0.0
    sum_p = 0.0
    sum_pq = 0.0
    max_n = 0.0
    for a in range(num):
        n = f[U(edge_n + a)]
        if n > 0.0:
            q = f[U(edge_q + a)]
            sum_n += n
            sum_p += f[U(probs + a)]
            sum_pq += f[U(probs + a)] * q
            if n > max_n:
                max_n = n
    raw_value = f[U(nb + RAW_VALUE)]
    if sum_n > 0.0:
        v_mix = (raw_value + sum_n / sum_p * sum_pq) / (1.0 + sum_n)  # Gumbel MuZero eq. 33
    else:
        v_mix = raw_value
    lo = np.inf
    hi = -np.inf
    for a in range(num):
        if at_root and mem[U(mask + a)] == 0:
            f[U(raw_q + a)] = 0.0
            continue
        f[U(raw_q + a)] = f[U(edge_q + a)] if f[U(edge_n + a)] > 0.0 else v_mix
        lo = min(lo, f[U(raw_q + a)])
        hi = max(hi, f[U(raw_q + a)])
    scale = (f[U(lay.params + P_C_VISIT)] + max_n) * f[U(lay.params + P_C_SCALE)]  # sigma, Gumbel MuZero eq. 8
    span = max(hi - lo, RESCALE_EPS)
    for a in range(num):
        if at_root and mem[U(mask + a)] == 0:
            f[U(sigma + a)] = 0.0
        else:
            f[U(sigma + a)] = scale * ((f[U(raw_q + a)] - lo) / span)


@njit(cache=True, error_model="numpy")
def gumbel_root_select(f, mem, lay, b, nb):
    """Sequential halving: among legal actions whose visits equal the schedule entry,
    argmax g(a) + logits(a) + sigma(completed q(a))."""
    num = lay.actions
    logits = lay.logits + b * num
    completed_sigma(f, mem, lay, b, nb, logits, True)
    sigma = lay.scratch + 2 * num
    legal = lay.legal + b * num
    num_legal = 0
    for a in range(num):
        if mem[U(legal + a)] != 0:
            num_legal += 1
    m = min(int(f[U(lay.params + P_MAX_CONSIDERED)]), num_legal)
    target = mem[U(lay.table + m * lay.sims + int(f[U(nb + VISITS)]) - 1)]  # root visits - 1 = simulations done
    edge_n = row(lay, nb, EDGE_N)
    gumbel = lay.gumbel + b * num
    best = -np.inf
    best_a = -1
    for a in range(num):
        if mem[U(legal + a)] == 0 or f[U(edge_n + a)] != target:
            continue
        score = f[U(gumbel + a)] + f[U(logits + a)] + f[U(sigma + a)]
        if score > best:
            best = score
            best_a = a
    return best_a


@njit(cache=True, error_model="numpy")
def gumbel_interior_select(f, mem, lay, b, nb):
    """Deterministic selection (Gumbel MuZero sec. 5): argmax pi'(a) - N(a) / (1 + sum_b N(b)),
    pi' = softmax(logits + sigma(completed q))."""
    num = lay.actions
    logits = row(lay, nb, POLICY)  # Gumbel mode keeps the logits there
    completed_sigma(f, mem, lay, b, nb, logits, False)
    raw_q, sigma, improved = lay.scratch + num, lay.scratch + 2 * num, lay.scratch + 3 * num
    for a in range(num):
        f[U(raw_q + a)] = f[U(logits + a)] + f[U(sigma + a)]  # reuse raw_q as the improved logits
    softmax_into(f, raw_q, improved, num, mem, 0, False)
    edge_n = row(lay, nb, EDGE_N)
    sum_n = 0.0
    for a in range(num):
        sum_n += f[U(edge_n + a)]
    best = -np.inf
    best_a = -1
    for a in range(num):
        score = f[U(improved + a)] - f[U(edge_n + a)] / (1.0 + sum_n)
        if score > best:
            best = score
            best_a = a
    return best_a


@njit(cache=True, error_model="numpy")
def clear_edges(f, lay, nb):
    """Mark the node at nb opened, with no children and no edge visits yet."""
    num = lay.actions
    edge_q, edge_n, child = row(lay, nb, EDGE_Q), row(lay, nb, EDGE_N), row(lay, nb, CHILD)
    for a in range(num):
        f[U(child + a)] = -1.0
        f[U(edge_q + a)] = 0.0
        f[U(edge_n + a)] = 0.0
    f[U(nb + OPENED)] = 1.0


@njit(cache=True, error_model="numpy")
def open_node(f, mem, lay, nb):
    """First pass of selection through the interior node at nb: clear its edges, and in
    pUCT mode turn its logits into the prior = softmax over all actions, in place (no
    mask below the root)."""
    clear_edges(f, lay, nb)
    if f[U(lay.params + P_GUMBEL)] == 0.0:
        policy = row(lay, nb, POLICY)
        softmax_into(f, policy, policy, lay.actions, mem, 0, False)


@njit(cache=True, error_model="numpy")
def select_leaf(f, mem, lay, b):
    """Descend tree b from the root to an unexpanded edge; return (parent node, action,
    parent depth)."""
    gumbel_mode = f[U(lay.params + P_GUMBEL)] != 0.0
    node = 0
    depth = 0
    while True:
        nb = node_at(lay, b, node)
        if f[U(nb + OPENED)] == 0.0:
            open_node(f, mem, lay, nb)
        if gumbel_mode:
            if node == 0:
                a = gumbel_root_select(f, mem, lay, b, nb)
            else:
                a = gumbel_interior_select(f, mem, lay, b, nb)
        else:
            a = puct_select(f, mem, lay, b, nb, node == 0)
        if a < 0:  # cannot happen with finite inputs; never index with -1
            raise RuntimeError("MCTS selection found no action")
        child = int(f[U(row(lay, nb, CHILD) + a)])
        if child < 0:
            return node, a, depth
        node = child
        depth += 1
