"""Numba kernels of the batched tree: expansion, backup, pUCT / Gumbel selection, root statistics.

The B trees live in preallocated arrays indexed [b, node]; node 0 is the root and the
leaf created at simulation s is node s + 1. Every kernel loops over the batch rows, which
never share state. Floating-point operations are written in the same order as in
`reference.py` so both give bit-identical results (tests compare with ==).

Array layout (N = num_simulations + 1 nodes, A actions):
    nodes_f  [B, N, 4] float64  VALUE_SUM, REWARD (edge reward into the node), RAW_VALUE
                                (network value), PREFIX (value prefix, EfficientZero)
    nodes_i  [B, N, 4] int32    VISITS (incl. own expansion), PARENT, DEPTH, ACTION (edge from parent)
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
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

VALUE_SUM, REWARD, RAW_VALUE, PREFIX = 0, 1, 2, 3
VISITS, PARENT, DEPTH, ACTION = 0, 1, 2, 3
PRIOR, LOGIT, EDGE_Q, EDGE_N = 0, 1, 2, 3
SEL_PARENT, SEL_ACTION, SEL_RESET = 0, 1, 2

# params vector (floats; flags are 0.0 / 1.0)
P_C1, P_C2, P_GAMMA_SIGN, P_UNVISITED_PARENT, P_GUMBEL, P_C_VISIT, P_C_SCALE = 0, 1, 2, 3, 4, 5, 6
P_VALUE_PREFIX, P_HORIZON, P_MAX_CONSIDERED, P_NOISE_FRACTION = 7, 8, 9, 10
NUM_PARAMS = 11

RESCALE_EPS = 1e-8  # floor of the min-max range when rescaling completed Q (Gumbel)

# Kernel status codes (the Python side turns them into ValueErrors).
OK, NON_FINITE = 0, 1


@njit(cache=True)
def _softmax_into(x, mask, use_mask, out):
    """out = softmax(x) over the entries where mask (or all if not use_mask); others 0."""
    num = x.shape[0]
    mx = -np.inf
    for a in range(num):
        if (not use_mask or mask[a]) and x[a] > mx:
            mx = x[a]
    total = 0.0
    for a in range(num):
        if not use_mask or mask[a]:
            out[a] = math.exp(x[a] - mx)
            total += out[a]
        else:
            out[a] = 0.0
    for a in range(num):
        out[a] = out[a] / total


@njit(cache=True)
def _child_q(nodes_f, nodes_i, b, child, gamma_sign):
    """Q of the edge into `child` from its parent's view: r + gamma * sign * mean value."""
    mean = nodes_f[b, child, VALUE_SUM] / nodes_i[b, child, VISITS]
    return nodes_f[b, child, REWARD] + gamma_sign * mean


@njit(cache=True)
def _normalize(q, lo, hi):
    """Tree min-max normalisation (MuZero appendix B), clipped to [0, 1]; 0 before a range exists."""
    if hi > lo:
        x = (q - lo) / (hi - lo)
        if x < 0.0:
            return 0.0
        if x > 1.0:
            return 1.0
        return x
    return 0.0


@njit(cache=True)
def _puct_select(nodes_f, nodes_i, children, edges_f, legal, minmax, params, b, node):
    """argmax_a  Qnorm(s,a) + P(s,a) * sqrt(N(s)) / (1 + N(s,a)) * (c1 + log((N(s) + c2 + 1) / c2))."""
    c1 = params[P_C1]
    c2 = params[P_C2]
    lo = minmax[b, 0]
    hi = minmax[b, 1]
    parent_n = float(nodes_i[b, node, VISITS])
    pb_c = (c1 + math.log((parent_n + c2 + 1.0) / c2)) * math.sqrt(parent_n)  # MuZero eq. 2
    if params[P_UNVISITED_PARENT] != 0.0:
        unvisited = _normalize(nodes_f[b, node, VALUE_SUM] / parent_n, lo, hi)
    else:
        unvisited = 0.0
    prior = edges_f[b, node, PRIOR]
    edge_q = edges_f[b, node, EDGE_Q]
    edge_n = edges_f[b, node, EDGE_N]
    at_root = node == 0
    best = -np.inf
    best_a = -1
    for a in range(prior.shape[0]):
        if at_root and not legal[b, a]:
            continue
        visits = edge_n[a]
        value_score = unvisited if visits == 0.0 else _normalize(edge_q[a], lo, hi)
        score = value_score + prior[a] * pb_c / (1.0 + visits)
        if score > best:
            best = score
            best_a = a
    return best_a


@njit(cache=True)
def _completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, node, probs, raw_q, sigma):
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
    _softmax_into(edges_f[b, node, LOGIT], row_mask, use_mask, probs)
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
        if use_mask and not row_mask[a]:
            raw_q[a] = 0.0
            continue
        raw_q[a] = edge_q[a] if edge_n[a] > 0.0 else v_mix
        lo = min(lo, raw_q[a])
        hi = max(hi, raw_q[a])
    scale = (params[P_C_VISIT] + max_n) * params[P_C_SCALE]  # sigma, Gumbel MuZero eq. 8
    span = max(hi - lo, RESCALE_EPS)
    for a in range(num):
        if use_mask and not row_mask[a]:
            sigma[a] = 0.0
        else:
            sigma[a] = scale * ((raw_q[a] - lo) / span)


@njit(cache=True)
def _gumbel_root_select(nodes_f, nodes_i, children, edges_f, legal, gumbel, table, params, b, scratch):
    """Sequential halving: among legal actions whose visits equal the schedule entry,
    argmax g(a) + logits(a) + sigma(completed q(a))."""
    probs, raw_q, sigma = scratch[0], scratch[1], scratch[2]
    _completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, 0, probs, raw_q, sigma)
    num_legal = 0
    for a in range(children.shape[2]):
        if legal[b, a]:
            num_legal += 1
    m = min(int(params[P_MAX_CONSIDERED]), num_legal)
    target = table[m, nodes_i[b, 0, VISITS] - 1]  # root visits - 1 = simulations done
    best = -np.inf
    best_a = -1
    for a in range(children.shape[2]):
        if not legal[b, a] or edges_f[b, 0, EDGE_N, a] != target:
            continue
        score = gumbel[b, a] + edges_f[b, 0, LOGIT, a] + sigma[a]
        if score > best:
            best = score
            best_a = a
    return best_a


@njit(cache=True)
def _gumbel_interior_select(nodes_f, nodes_i, children, edges_f, legal, params, b, node, scratch):
    """Deterministic selection (Gumbel MuZero sec. 5): argmax pi'(a) - N(a) / (1 + sum_b N(b)),
    pi' = softmax(logits + sigma(completed q))."""
    probs, raw_q, sigma, improved = scratch[0], scratch[1], scratch[2], scratch[3]
    _completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, node, probs, raw_q, sigma)
    num = children.shape[2]
    for a in range(num):
        raw_q[a] = edges_f[b, node, LOGIT, a] + sigma[a]  # reuse raw_q as the improved logits
    _softmax_into(raw_q, legal[b], False, improved)
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


@njit(cache=True)
def _select_leaf(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params, b, scratch):
    """Descend from the root to an unexpanded edge; return (parent node, action)."""
    node = 0
    while True:
        if params[P_GUMBEL] != 0.0:
            if node == 0:
                a = _gumbel_root_select(nodes_f, nodes_i, children, edges_f, legal, gumbel, table, params, b, scratch)
            else:
                a = _gumbel_interior_select(nodes_f, nodes_i, children, edges_f, legal, params, b, node, scratch)
        else:
            a = _puct_select(nodes_f, nodes_i, children, edges_f, legal, minmax, params, b, node)
        child = children[b, node, a]
        if child < 0:
            return node, a
        node = child


@njit(cache=True)
def _backup(nodes_f, nodes_i, edges_f, minmax, params, b, leaf, value):
    """G = v at the leaf; for each node up to the root: add G, then G = r + gamma * sign * G."""
    gamma_sign = params[P_GAMMA_SIGN]
    g = value
    node = leaf
    while True:
        nodes_f[b, node, VALUE_SUM] += g
        nodes_i[b, node, VISITS] += 1
        if node == 0:
            return
        q = _child_q(nodes_f, nodes_i, b, node, gamma_sign)
        minmax[b, 0] = min(minmax[b, 0], q)
        minmax[b, 1] = max(minmax[b, 1], q)
        parent = nodes_i[b, node, PARENT]
        action = nodes_i[b, node, ACTION]
        edges_f[b, parent, EDGE_Q, action] = q
        edges_f[b, parent, EDGE_N, action] = nodes_i[b, node, VISITS]
        g = nodes_f[b, node, REWARD] + gamma_sign * g
        node = parent


@njit(cache=True)
def _select_and_gather(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                       store, gathered, sel, b, scratch):
    """Pick row b's next leaf, record it in sel and copy its parent's latent bytes out."""
    parent, action = _select_leaf(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params, b, scratch)
    sel[SEL_PARENT, b] = parent
    sel[SEL_ACTION, b] = action
    sel[SEL_RESET, b] = 1 if nodes_i[b, parent, DEPTH] % int(params[P_HORIZON]) == 0 else 0
    gathered[b, :] = store[b, parent, :]


@njit(cache=True)
def init_roots(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
               root_logits, root_value, dirichlet, store, staged, gathered, sel):
    """Expand the B roots (prior = softmax over legal, mixed with Dirichlet noise), store
    their latents and select the first leaves. Returns a status code."""
    num_actions = children.shape[2]
    scratch = np.empty((4, num_actions))
    frac = params[P_NOISE_FRACTION]
    for b in range(nodes_f.shape[0]):
        if not math.isfinite(root_value[b]):
            return NON_FINITE
        for a in range(num_actions):
            if not math.isfinite(root_logits[b, a]):
                return NON_FINITE
            edges_f[b, 0, LOGIT, a] = root_logits[b, a]
        prior = edges_f[b, 0, PRIOR]
        _softmax_into(root_logits[b], legal[b], True, prior)
        if frac > 0.0:
            for a in range(num_actions):
                if legal[b, a]:
                    prior[a] = (1.0 - frac) * prior[a] + frac * dirichlet[b, a]  # AlphaZero root noise
        nodes_f[b, 0, RAW_VALUE] = root_value[b]
        nodes_f[b, 0, VALUE_SUM] = root_value[b]
        nodes_i[b, 0, VISITS] = 1
        store[b, 0, :] = staged[b, :]
        _select_and_gather(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                           store, gathered, sel, b, scratch)
    return OK


@njit(cache=True)
def expand_backup_select(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                         node, reward, value, logits, store, staged, gathered, sel, select_next):
    """One simulation's tail for all rows: expand node `node` under the pending (parent,
    action) with the model outputs, back up its value, then (if select_next) select the
    next leaf and gather its parent's latent. Returns a status code."""
    num_actions = children.shape[2]
    scratch = np.empty((4, num_actions))
    value_prefix = params[P_VALUE_PREFIX] != 0.0
    for b in range(nodes_f.shape[0]):
        if not (math.isfinite(reward[b]) and math.isfinite(value[b])):
            return NON_FINITE
        for a in range(num_actions):
            if not math.isfinite(logits[b, a]):
                return NON_FINITE
        parent = sel[SEL_PARENT, b]
        children[b, parent, sel[SEL_ACTION, b]] = node
        nodes_i[b, node, PARENT] = parent
        nodes_i[b, node, ACTION] = sel[SEL_ACTION, b]
        nodes_i[b, node, DEPTH] = nodes_i[b, parent, DEPTH] + 1
        if value_prefix:
            # EfficientZero: the edge reward is the prefix increase, or the prefix itself
            # right after a reset of the LSTM segment.
            nodes_f[b, node, PREFIX] = reward[b]
            if sel[SEL_RESET, b] != 0:
                nodes_f[b, node, REWARD] = reward[b]
            else:
                nodes_f[b, node, REWARD] = reward[b] - nodes_f[b, parent, PREFIX]
        else:
            nodes_f[b, node, REWARD] = reward[b]
        nodes_f[b, node, RAW_VALUE] = value[b]
        for a in range(num_actions):
            edges_f[b, node, LOGIT, a] = logits[b, a]
        _softmax_into(logits[b], legal[b], False, edges_f[b, node, PRIOR])
        store[b, node, :] = staged[b, :]
        _backup(nodes_f, nodes_i, edges_f, minmax, params, b, node, value[b])
        if select_next:
            _select_and_gather(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                               store, gathered, sel, b, scratch)
    return OK


@njit(cache=True)
def root_statistics(nodes_f, nodes_i, children, edges_f, legal, gumbel, params,
                    visit_counts, q_values, improved, gumbel_action, root_value):
    """Fill the per-row outputs: root child visits [B, A], completed Q [B, A], root value [B];
    in Gumbel mode also the improved policy [B, A] and the action A_{n+1} [B]: among the
    most-visited legal actions, argmax g + logits + sigma(completed q)."""
    num_actions = children.shape[2]
    scratch = np.empty((3, num_actions))
    probs, sigma = scratch[0], scratch[1]
    for b in range(nodes_f.shape[0]):
        _completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, 0, probs, q_values[b], sigma)
        root_value[b] = nodes_f[b, 0, VALUE_SUM] / nodes_i[b, 0, VISITS]
        max_n = 0
        for a in range(num_actions):
            visit_counts[b, a] = int(edges_f[b, 0, EDGE_N, a])
            max_n = max(max_n, visit_counts[b, a])
        if params[P_GUMBEL] == 0.0:
            continue
        for a in range(num_actions):
            scratch[2, a] = edges_f[b, 0, LOGIT, a] + sigma[a]
        _softmax_into(scratch[2], legal[b], True, improved[b])
        best = -np.inf
        for a in range(num_actions):
            if legal[b, a] and visit_counts[b, a] == max_n:
                score = gumbel[b, a] + edges_f[b, 0, LOGIT, a] + sigma[a]
                if score > best:
                    best = score
                    gumbel_action[b] = a
