"""Numba entry points of the batched search: expand the roots, then per simulation expand
the pending leaves, back up their values and select the next leaves (one call), and
finally the outputs. Each kernel loops over the batch rows, which never share state. See
`layout.py` for the buffers and `select.py` for the selection rules.

The entry points take the two flat tree buffers (`tree.unpack` cuts them into views)
and the model's outputs as they come (float32 or float64, any strides): every array
argument costs numba time to unbox, and a B=1 search makes one call per simulation.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from wmdist.search.layout import (
    ACTION, BAD_SHAPE, DEPTH, EDGE_N, EDGE_Q, GATHERED, LOGIT, NO_LEGAL, NON_FINITE, OK,
    P_GAMMA_SIGN, P_GUMBEL, P_HORIZON, P_NOISE_FRACTION, P_VALUE_PREFIX, PARENT, PREFIX, PRIOR, RAW_VALUE,
    REWARD, SEL_ACTION, SEL_PARENT, SEL_RESET, STAGED, VALUE_SUM, VISITS,
)
from wmdist.search.noise import dirichlet_row
from wmdist.search.select import child_q, completed_sigma, open_node, select_leaf, softmax_into
from wmdist.search.tree import unpack


@njit(cache=True, error_model="numpy")
def _copy_words(src, dst):
    """dst[:] = src[:] for one latent row of uint64 words (a plain loop: cheaper than a
    numba slice assignment for rows of a few dozen words)."""
    for w in range(src.shape[0]):
        dst[w] = src[w]


@njit(cache=True, error_model="numpy")
def _new_node(nodes_f, nodes_i, b, node):
    """Clear node `node` of row b: no visits, not opened (its edge rows are cleared by
    select.open_node the first time selection passes through it)."""
    for k in range(nodes_f.shape[2]):
        nodes_f[b, node, k] = 0.0
    for k in range(nodes_i.shape[2]):
        nodes_i[b, node, k] = 0


@njit(cache=True, error_model="numpy")
def _backup(nodes_f, nodes_i, edges_f, minmax, params, b, leaf, value):
    """G = v at the leaf; for each node up to the root: add G, then G = r + gamma * sign * G."""
    gamma_sign = params[P_GAMMA_SIGN]
    g = 1.0 * value  # float64 whatever the model's dtype
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
def _select_and_gather(params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children,
                       sel, store, io, b):
    """Pick row b's next leaf, record it in sel and copy its parent's latent bytes out."""
    parent, action = select_leaf(nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params, b, scratch)
    sel[SEL_PARENT, b] = parent
    sel[SEL_ACTION, b] = action
    sel[SEL_RESET, b] = 1 if nodes_i[b, parent, DEPTH] % int(params[P_HORIZON]) == 0 else 0
    _copy_words(store[b, parent], io[GATHERED, b])


@njit(cache=True, error_model="numpy")
def init_roots(tree_f, tree_i, sel, store, io, root_logits, root_value, legal_in, noise):
    """Expand the B roots (prior = softmax over legal, mixed with Dirichlet noise), store
    their latents and select the first leaves. `noise` is draw_root_noise's [B, A] draws
    (Gammas in pUCT mode, Gumbels in Gumbel mode) or [0, 0] for none. Returns a status code."""
    params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children = unpack(tree_f, tree_i)
    num_actions = children.shape[2]
    has_noise = noise.shape[0] > 0
    gumbel_mode = params[P_GUMBEL] != 0.0
    frac = params[P_NOISE_FRACTION]
    for b in range(nodes_f.shape[0]):
        if not math.isfinite(root_value[b]):
            return NON_FINITE
        num_legal = 0
        for a in range(num_actions):
            if not math.isfinite(root_logits[b, a]):
                return NON_FINITE
            legal[b, a] = 1 if legal_in[b, a] else 0
            num_legal += legal[b, a]
            gumbel[b, a] = noise[b, a] if gumbel_mode and has_noise else 0.0
        if num_legal == 0:
            return NO_LEGAL
        minmax[b, 0] = np.inf
        minmax[b, 1] = -np.inf
        _new_node(nodes_f, nodes_i, b, 0)
        for a in range(num_actions):
            edges_f[b, 0, LOGIT, a] = root_logits[b, a]
        open_node(nodes_i, children, edges_f, legal, params, b, 0)
        prior = edges_f[b, 0, PRIOR]
        softmax_into(edges_f[b, 0, LOGIT], legal[b], True, prior)  # the root's prior: legal actions only
        if frac > 0.0 and has_noise and not gumbel_mode:
            dirichlet = scratch[3]
            dirichlet_row(noise[b], legal[b], dirichlet)
            for a in range(num_actions):
                if legal[b, a] != 0:
                    prior[a] = (1.0 - frac) * prior[a] + frac * dirichlet[a]  # AlphaZero root noise
        nodes_f[b, 0, RAW_VALUE] = root_value[b]
        nodes_f[b, 0, VALUE_SUM] = root_value[b]
        nodes_i[b, 0, VISITS] = 1
        _copy_words(io[STAGED, b], store[b, 0])
        _select_and_gather(params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children,
                               sel, store, io, b)
    return OK


@njit(cache=True, error_model="numpy")
def expand_backup_select(tree_f, tree_i, sel, store, io, reward, value, logits, node, select_next):
    """One simulation's tail for all rows: expand node `node` under the pending (parent,
    action) with the model outputs (reward [B], value [B], logits [B, A]), back up its
    value, then (if select_next) select the next leaf and gather its parent's latent.
    Returns a status code (BAD_SHAPE before anything is written)."""
    params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children = unpack(tree_f, tree_i)
    batch, num_actions = legal.shape
    if reward.shape[0] != batch or value.shape[0] != batch or logits.shape != (batch, num_actions):
        return BAD_SHAPE
    value_prefix = params[P_VALUE_PREFIX] != 0.0
    for b in range(batch):
        # A non-finite output aborts the search (the workspace needs no clean-up: nodes
        # are cleared when created), so rows are checked as they are expanded.
        if not (math.isfinite(reward[b]) and math.isfinite(value[b])):
            return NON_FINITE
        finite = True
        for a in range(num_actions):
            x = logits[b, a]
            finite &= math.isfinite(x)
            edges_f[b, node, LOGIT, a] = x
        if not finite:
            return NON_FINITE
        parent = sel[SEL_PARENT, b]
        _new_node(nodes_f, nodes_i, b, node)
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
        _copy_words(io[STAGED, b], store[b, node])
        _backup(nodes_f, nodes_i, edges_f, minmax, params, b, node, value[b])
        if select_next:
            _select_and_gather(params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children,
                               sel, store, io, b)
    return OK


@njit(cache=True, error_model="numpy")
def _visit_policy_row(counts, legal, temperature, uniform, p64, policy):
    """policy [A] float32 proportional to N(a)^(1/T) over legal actions (one-hot argmax,
    lowest index on ties, if T == 0); returns the action: that argmax, or the draw from
    the float64 policy p64's CDF with `uniform` in [0, 1) (never a zero-probability
    action). The arithmetic of `engine.visit_policy` + `engine.sample_actions`, with sums
    in index order."""
    num = counts.shape[0]
    best = 0
    for a in range(num):
        if counts[a] * legal[a] > counts[best] * legal[best]:
            best = a
    if temperature == 0.0:
        policy[:] = 0.0
        policy[best] = 1.0
        return best
    top = float(counts[best] * legal[best])
    inv_t = 1.0 / temperature
    total = 0.0
    for a in range(num):
        p64[a] = (counts[a] * legal[a] / top) ** inv_t  # (N / max N)^(1/T) <= 1: no overflow
        total += p64[a]
    cdf = 0.0
    for a in range(num):
        p64[a] = p64[a] / total
        policy[a] = p64[a]
        cdf += p64[a]
    x = (1.0 - uniform) * cdf  # in (0, cdf]
    action = 0
    cdf = 0.0
    for a in range(num):
        cdf += p64[a]
        if cdf < x:
            action += 1
    return min(action, num - 1)


@njit(cache=True, error_model="numpy")
def finish(tree_f, tree_i, temperature, uniforms, visit_counts, policy, action, root_value, q_values):
    """Fill the outputs of every row: root child visits [B, A] int64, completed Q [B, A]
    float32, root value [B] float32, and the policy [B, A] float32 + action [B] int64.
    pUCT: the visit-count policy at `temperature`, the action drawn with uniforms [B]
    (argmax if temperature == 0). Gumbel: the improved policy softmax(logits +
    sigma(completed q)) and the action A_{n+1}: among the most-visited legal actions,
    argmax g + logits + sigma(completed q)."""
    params, minmax, gumbel, scratch, nodes_f, edges_f, legal, table, nodes_i, children = unpack(tree_f, tree_i)
    num_actions = children.shape[2]
    probs, raw_q, sigma, improved = scratch[0], scratch[1], scratch[2], scratch[3]
    for b in range(nodes_f.shape[0]):
        completed_sigma(nodes_f, nodes_i, children, edges_f, legal, params, b, 0, probs, raw_q, sigma)
        q_values[b, :] = raw_q
        root_value[b] = nodes_f[b, 0, VALUE_SUM] / nodes_i[b, 0, VISITS]
        max_n = 0
        for a in range(num_actions):
            visit_counts[b, a] = int(edges_f[b, 0, EDGE_N, a])
            max_n = max(max_n, visit_counts[b, a])
        if params[P_GUMBEL] == 0.0:
            uniform = uniforms[b] if uniforms.shape[0] > 0 else 0.0
            action[b] = _visit_policy_row(visit_counts[b], legal[b], temperature, uniform, probs, policy[b])
            continue
        for a in range(num_actions):
            probs[a] = edges_f[b, 0, LOGIT, a] + sigma[a]  # reuse probs as the improved logits
        softmax_into(probs, legal[b], True, improved)
        policy[b, :] = improved
        best = -np.inf
        action[b] = 0
        for a in range(num_actions):
            if legal[b, a] != 0 and visit_counts[b, a] == max_n:
                score = gumbel[b, a] + edges_f[b, 0, LOGIT, a] + sigma[a]
                if score > best:
                    best = score
                    action[b] = a
