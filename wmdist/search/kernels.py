"""Numba entry points of the batched search: expand the roots, then per simulation expand
the pending leaves, back up their values and select the next leaves; finally the root
statistics. Each kernel loops over the batch rows, which never share state. See
`layout.py` for the arrays and `select.py` for the selection rules.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from wmdist.search.layout import (
    ACTION, DEPTH, EDGE_N, EDGE_Q, HAS_PRIOR, LOGIT, NON_FINITE, OK, P_GAMMA_SIGN, P_GUMBEL,
    P_HORIZON, P_NOISE_FRACTION, P_VALUE_PREFIX, PARENT, PREFIX, PRIOR, RAW_VALUE, REWARD,
    SEL_ACTION, SEL_PARENT, SEL_RESET, VALUE_SUM, VISITS,
)
from wmdist.search.select import child_q, completed_sigma, select_leaf, softmax_into


@njit(cache=True, error_model="numpy")
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
        q = child_q(nodes_f, nodes_i, b, node, gamma_sign)
        minmax[b, 0] = min(minmax[b, 0], q)
        minmax[b, 1] = max(minmax[b, 1], q)
        parent = nodes_i[b, node, PARENT]
        action = nodes_i[b, node, ACTION]
        edges_f[b, parent, EDGE_Q, action] = q
        edges_f[b, parent, EDGE_N, action] = nodes_i[b, node, VISITS]
        g = nodes_f[b, node, REWARD] + gamma_sign * g
        node = parent


@njit(cache=True, error_model="numpy")
def _select_and_gather(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                       store, gathered, sel, b, scratch):
    """Pick row b's next leaf, record it in sel and copy its parent's latent bytes out."""
    parent, action = select_leaf(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params, b, scratch)
    sel[SEL_PARENT, b] = parent
    sel[SEL_ACTION, b] = action
    sel[SEL_RESET, b] = 1 if nodes_i[b, parent, DEPTH] % int(params[P_HORIZON]) == 0 else 0
    gathered[b, :] = store[b, parent, :]


@njit(cache=True, error_model="numpy")
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
        softmax_into(root_logits[b], legal[b], True, prior)
        if frac > 0.0:
            for a in range(num_actions):
                if legal[b, a]:
                    prior[a] = (1.0 - frac) * prior[a] + frac * dirichlet[b, a]  # AlphaZero root noise
        nodes_i[b, 0, HAS_PRIOR] = 1
        nodes_f[b, 0, RAW_VALUE] = root_value[b]
        nodes_f[b, 0, VALUE_SUM] = root_value[b]
        nodes_i[b, 0, VISITS] = 1
        store[b, 0, :] = staged[b, :]
        _select_and_gather(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                           store, gathered, sel, b, scratch)
    return OK


@njit(cache=True, error_model="numpy")
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
        store[b, node, :] = staged[b, :]
        _backup(nodes_f, nodes_i, edges_f, minmax, params, b, node, value[b])
        if select_next:
            _select_and_gather(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params,
                               store, gathered, sel, b, scratch)
    return OK


@njit(cache=True, error_model="numpy")
def root_statistics(nodes_f, nodes_i, children, edges_f, legal, gumbel, params,
                    visit_counts, q_values, improved, gumbel_action, root_value):
    """Fill the per-row outputs: root child visits [B, A], completed Q [B, A], root value [B];
    in Gumbel mode also the improved policy [B, A] and the action A_{n+1} [B]: among the
    most-visited legal actions, argmax g + logits + sigma(completed q)."""
    num_actions = children.shape[2]
    scratch = np.empty((3, num_actions))
    probs, sigma = scratch[0], scratch[1]
    for b in range(nodes_f.shape[0]):
        completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, 0, probs, q_values[b], sigma)
        root_value[b] = nodes_f[b, 0, VALUE_SUM] / nodes_i[b, 0, VISITS]
        max_n = 0
        for a in range(num_actions):
            visit_counts[b, a] = int(edges_f[b, 0, EDGE_N, a])
            max_n = max(max_n, visit_counts[b, a])
        if params[P_GUMBEL] == 0.0:
            continue
        for a in range(num_actions):
            scratch[2, a] = edges_f[b, 0, LOGIT, a] + sigma[a]
        softmax_into(scratch[2], legal[b], True, improved[b])
        best = -np.inf
        for a in range(num_actions):
            if legal[b, a] and visit_counts[b, a] == max_n:
                score = gumbel[b, a] + edges_f[b, 0, LOGIT, a] + sigma[a]
                if score > best:
                    best = score
                    gumbel_action[b] = a
