"""Selection rules of the batched search as numba helpers: pUCT (MuZero eq. 2) and Gumbel
MuZero (sequential halving at the root, deterministic interior selection, completed Q).

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
    EDGE_N, EDGE_Q, LOGIT, OPENED, P_C1, P_C2, P_C_SCALE, P_C_VISIT, P_GUMBEL, P_MAX_CONSIDERED,
    P_UNVISITED_PARENT, PRIOR, RAW_VALUE, RESCALE_EPS, REWARD, VALUE_SUM, VISITS,
)


@njit(cache=True, error_model="numpy")
def softmax_into(x, mask, use_mask, out):
    """out = softmax(x) over the entries where mask != 0 (or all if not use_mask); others 0."""
    num = x.shape[0]
    mx = -np.inf
    for a in range(num):
        if (not use_mask or mask[a] != 0) and x[a] > mx:
            mx = x[a]
    total = 0.0
    for a in range(num):
        if not use_mask or mask[a] != 0:
            out[a] = math.exp(x[a] - mx)
            total += out[a]
        else:
            out[a] = 0.0
    for a in range(num):
        out[a] = out[a] / total


@njit(cache=True, error_model="numpy")
def child_q(nodes_f, nodes_i, b, child, gamma_sign):
    """Q of the edge into `child` from its parent's view: r + gamma * sign * mean value."""
    mean = nodes_f[b, child, VALUE_SUM] / nodes_i[b, child, VISITS]
    return nodes_f[b, child, REWARD] + gamma_sign * mean


@njit(cache=True, error_model="numpy")
def minmax_scale(lo, hi):
    """1 / (max - min) of the tree's Q range, or 0 before a range exists (all scores 0)."""
    return 1.0 / (hi - lo) if hi > lo else 0.0


@njit(cache=True, error_model="numpy")
def normalize(q, lo, inv_span):
    """Tree min-max normalisation (MuZero appendix B), clipped to [0, 1]."""
    x = (q - lo) * inv_span
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@njit(cache=True, error_model="numpy")
def puct_select(nodes_f, nodes_i, children, edges_f, legal, minmax, params, b, node, scores):
    """argmax_a  Qnorm(s,a) + P(s,a) * sqrt(N(s)) / (1 + N(s,a)) * (c1 + log((N(s) + c2 + 1) / c2)).

    Scores go through `scores` [A] in a branch-free loop (vectorisable), then one argmax
    pass applies the root mask and takes the lowest index on ties.
    """
    c1 = params[P_C1]
    c2 = params[P_C2]
    inv_span = minmax_scale(minmax[b, 0], minmax[b, 1])
    lo = minmax[b, 0] if inv_span > 0.0 else 0.0  # no range yet (lo = +inf): every score 0
    parent_n = float(nodes_i[b, node, VISITS])
    pb_c = (c1 + math.log((parent_n + c2 + 1.0) / c2)) * math.sqrt(parent_n)  # MuZero eq. 2
    if params[P_UNVISITED_PARENT] != 0.0:
        unvisited = normalize(nodes_f[b, node, VALUE_SUM] / parent_n, lo, inv_span)
    else:
        unvisited = 0.0
    prior = edges_f[b, node, PRIOR]
    edge_q = edges_f[b, node, EDGE_Q]
    edge_n = edges_f[b, node, EDGE_N]
    num = prior.shape[0]
    for a in range(num):
        visits = edge_n[a]
        value_score = unvisited if visits == 0.0 else normalize(edge_q[a], lo, inv_span)
        scores[a] = value_score + prior[a] * pb_c / (1.0 + visits)
    at_root = node == 0
    best = -np.inf
    best_a = -1
    for a in range(num):
        if scores[a] > best and (not at_root or legal[b, a] != 0):
            best = scores[a]
            best_a = a
    return best_a


@njit(cache=True, error_model="numpy")
def completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, node, probs, raw_q, sigma):
    """Gumbel MuZero completed Q at `node` (eq. 33 mixed value for unvisited actions).

    Fills raw_q [A] (completed Q), sigma [A] = (c_visit + max_b N(b)) * c_scale * rescaled
    completed Q (min-max over the node's actions, floor RESCALE_EPS) and probs [A] = prior
    softmax(logits). At the root only legal actions count (illegal raw_q = sigma = 0).
    """
    num = children.shape[2]
    use_mask = node == 0
    row_mask = legal[b]
    edge_q = edges_f[b, node, EDGE_Q]
    edge_n = edges_f[b, node, EDGE_N]
    softmax_into(edges_f[b, node, LOGIT], row_mask, use_mask, probs)
    sum_n = 0.0
    sum_p = 0.0
    sum_pq = 0.0
    max_n = 0.0
    for a in range(num):
        n = edge_n[a]
        if n > 0.0:
            q = edge_q[a]
            sum_n += n
            sum_p += probs[a]
            sum_pq += probs[a] * q
            if n > max_n:
                max_n = n
    raw_value = nodes_f[b, node, RAW_VALUE]
    if sum_n > 0.0:
        v_mix = (raw_value + sum_n / sum_p * sum_pq) / (1.0 + sum_n)  # Gumbel MuZero eq. 33
    else:
        v_mix = raw_value
    lo = np.inf
    hi = -np.inf
    for a in range(num):
        if use_mask and row_mask[a] == 0:
            raw_q[a] = 0.0
            continue
        raw_q[a] = edge_q[a] if edge_n[a] > 0.0 else v_mix
        lo = min(lo, raw_q[a])
        hi = max(hi, raw_q[a])
    scale = (params[P_C_VISIT] + max_n) * params[P_C_SCALE]  # sigma, Gumbel MuZero eq. 8
    span = max(hi - lo, RESCALE_EPS)
    for a in range(num):
        if use_mask and row_mask[a] == 0:
            sigma[a] = 0.0
        else:
            sigma[a] = scale * ((raw_q[a] - lo) / span)


@njit(cache=True, error_model="numpy")
def gumbel_root_select(nodes_f, nodes_i, children, edges_f, legal, gumbel, table, params, b, scratch):
    """Sequential halving: among legal actions whose visits equal the schedule entry,
    argmax g(a) + logits(a) + sigma(completed q(a))."""
    probs, raw_q, sigma = scratch[0], scratch[1], scratch[2]
    completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, 0, probs, raw_q, sigma)
    num_legal = 0
    for a in range(children.shape[2]):
        if legal[b, a] != 0:
            num_legal += 1
    m = min(int(params[P_MAX_CONSIDERED]), num_legal)
    target = table[m, nodes_i[b, 0, VISITS] - 1]  # root visits - 1 = simulations done
    best = -np.inf
    best_a = -1
    for a in range(children.shape[2]):
        if legal[b, a] == 0 or edges_f[b, 0, EDGE_N, a] != target:
            continue
        score = gumbel[b, a] + edges_f[b, 0, LOGIT, a] + sigma[a]
        if score > best:
            best = score
            best_a = a
    return best_a


@njit(cache=True, error_model="numpy")
def gumbel_interior_select(nodes_f, nodes_i, children, edges_f, legal, params, b, node, scratch):
    """Deterministic selection (Gumbel MuZero sec. 5): argmax pi'(a) - N(a) / (1 + sum_b N(b)),
    pi' = softmax(logits + sigma(completed q))."""
    probs, raw_q, sigma, improved = scratch[0], scratch[1], scratch[2], scratch[3]
    completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, node, probs, raw_q, sigma)
    num = children.shape[2]
    for a in range(num):
        raw_q[a] = edges_f[b, node, LOGIT, a] + sigma[a]  # reuse raw_q as the improved logits
    softmax_into(raw_q, legal[b], False, improved)
    edge_n = edges_f[b, node, EDGE_N]
    sum_n = 0.0
    for a in range(num):
        sum_n += edge_n[a]
    best = -np.inf
    best_a = -1
    for a in range(num):
        score = improved[a] - edge_n[a] / (1.0 + sum_n)
        if score > best:
            best = score
            best_a = a
    return best_a


@njit(cache=True, error_model="numpy")
def open_node(nodes_i, children, edges_f, legal, params, b, node):
    """First pass of selection through `node`: no children, no edge visits yet, and in pUCT
    mode the prior = softmax of the logits over all actions (interior nodes: no mask)."""
    for a in range(children.shape[2]):
        children[b, node, a] = -1
        edges_f[b, node, EDGE_Q, a] = 0.0
        edges_f[b, node, EDGE_N, a] = 0.0
    if params[P_GUMBEL] == 0.0:
        softmax_into(edges_f[b, node, LOGIT], legal[b], False, edges_f[b, node, PRIOR])
    nodes_i[b, node, OPENED] = 1


@njit(cache=True, error_model="numpy")
def select_leaf(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params, b, scratch):
    """Descend from the root to an unexpanded edge; return (parent node, action)."""
    node = 0
    while True:
        if nodes_i[b, node, OPENED] == 0:
            open_node(nodes_i, children, edges_f, legal, params, b, node)
        if params[P_GUMBEL] != 0.0:
            if node == 0:
                a = gumbel_root_select(nodes_f, nodes_i, children, edges_f, legal, gumbel, table, params, b, scratch)
            else:
                a = gumbel_interior_select(nodes_f, nodes_i, children, edges_f, legal, params, b, node, scratch)
        else:
            a = puct_select(nodes_f, nodes_i, children, edges_f, legal, minmax, params, b, node, scratch[0])
        if a < 0:  # cannot happen with finite inputs; never index with -1 (numba wraps it)
            raise RuntimeError("MCTS selection found no action")
        child = children[b, node, a]
        if child < 0:
            return node, a
        node = child
