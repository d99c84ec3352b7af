"""Numba entry points of the batched search: expand the roots, then per simulation expand
the pending leaves, back up their values and select the next leaves (one call), and
finally the outputs. Each kernel loops over the batch rows, which never share state. See
`layout.py` for the buffer and `select.py` for the selection rules.

The entry points take the one flat buffer `mem` and the model's outputs as they come
(float32 or float64, any strides): every array argument costs numba time to unbox, and a
B=1 search makes one call per simulation.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from wmdist.search.layout import (
    ACTION,
    BAD_SHAPE,
    CHILD,
    EDGE_N,
    EDGE_Q,
    GATHERED,
    NO_LEGAL,
    NON_FINITE,
    OK,
    OPENED,
    P_GAMMA_SIGN,
    P_GUMBEL,
    P_HORIZON,
    P_NOISE_FRACTION,
    P_VALUE_PREFIX,
    PARENT,
    POLICY,
    PREFIX,
    RAW_VALUE,
    REWARD,
    STAGED,
    VALUE_SUM,
    VISITS,
)
from wmdist.search.noise import dirichlet_row
from wmdist.search.select import (
    U,
    clear_edges,
    completed_sigma,
    node_at,
    pb_c_table,
    row,
    select_leaf,
    softmax_into,
)
from wmdist.search.tree import layout_of


@njit(cache=True, error_model="numpy")
def _copy_latent(mem, lay, b, node, io_row, to_store):
    """Copy tree b's latent words between node `node` of the store and row b of io[io_row]
    (a plain loop: cheaper than a numba slice assignment for rows of a few words)."""
    store = lay.store + (b * lay.nodes + node) * lay.words
    io = lay.io + (io_row * lay.batch + b) * lay.words
    src, dst = (io, store) if to_store else (store, io)
    for w in range(lay.words):
        mem[U(dst + w)] = mem[U(src + w)]


@njit(cache=True, error_model="numpy")
def _backup(f, lay, b, leaf, value, gamma_sign):
    """G = v at the leaf; for each node up to the root: add G, then G = r + gamma * sign * G.
    Each edge's Q and N are mirrored into its parent's block for selection."""
    g = 1.0 * value  # float64 whatever the model's dtype
    minmax = lay.minmax + 2 * b
    node = leaf
    while True:
        nb = node_at(lay, b, node)
        f[U(nb + VALUE_SUM)] += g
        f[U(nb + VISITS)] += 1.0
        if node == 0:
            return
        q = f[U(nb + REWARD)] + gamma_sign * (f[U(nb + VALUE_SUM)] / f[U(nb + VISITS)])  # Q from the parent's view
        f[U(minmax)] = min(f[U(minmax)], q)
        f[U(minmax + 1)] = max(f[U(minmax + 1)], q)
        parent = int(f[U(nb + PARENT)])
        action = int(f[U(nb + ACTION)])
        pb = node_at(lay, b, parent)
        f[U(row(lay, pb, EDGE_Q) + action)] = q
        f[U(row(lay, pb, EDGE_N) + action)] = f[U(nb + VISITS)]
        g = f[U(nb + REWARD)] + gamma_sign * g
        node = parent


@njit(cache=True, error_model="numpy")
def _select_and_gather(f, mem, lay, b, horizon):
    """Pick row b's next leaf, record it in sel and copy its parent's latent words out."""
    parent, action, depth = select_leaf(f, mem, lay, b)
    mem[U(lay.sel + b)] = parent
    mem[U(lay.sel + lay.batch + b)] = action
    mem[U(lay.sel + 2 * lay.batch + b)] = 1 if depth % horizon == 0 else 0
    _copy_latent(mem, lay, b, parent, GATHERED, False)


@njit(cache=True, error_model="numpy")
def init_roots(mem, root_logits, root_value, legal_in, noise):
    """Expand the B roots (prior = softmax over legal, mixed with Dirichlet noise), store
    their latents and select the first leaves. `noise` is draw_root_noise's [B, A] draws
    (Gammas in pUCT mode, Gumbels in Gumbel mode) or [0, 0] for none. Returns a status code."""
    lay = layout_of(mem)
    f = mem.view(np.float64)
    num = lay.actions
    params = lay.params
    has_noise = noise.shape[0] > 0
    gumbel_mode = f[U(params + P_GUMBEL)] != 0.0
    frac = f[U(params + P_NOISE_FRACTION)]
    horizon = int(f[U(params + P_HORIZON)])
    pb_c_table(f, lay)
    for b in range(lay.batch):
        if not math.isfinite(root_value[b]):
            return NON_FINITE
        legal, logits, gumbel = lay.legal + b * num, lay.logits + b * num, lay.gumbel + b * num
        num_legal = 0
        for a in range(num):
            if not math.isfinite(root_logits[b, a]):
                return NON_FINITE
            mem[U(legal + a)] = 1 if legal_in[b, a] else 0
            num_legal += mem[U(legal + a)]
            f[U(gumbel + a)] = noise[b, a] if gumbel_mode and has_noise else 0.0
            f[U(logits + a)] = root_logits[b, a]
        if num_legal == 0:
            return NO_LEGAL
        f[U(lay.minmax + 2 * b)] = np.inf
        f[U(lay.minmax + 2 * b + 1)] = -np.inf
        nb = node_at(lay, b, 0)
        for k in range(VALUE_SUM, OPENED):
            f[U(nb + k)] = 0.0
        clear_edges(f, lay, nb)
        prior = row(lay, nb, POLICY)
        if gumbel_mode:
            for a in range(num):
                f[U(prior + a)] = f[U(logits + a)]  # Gumbel mode keeps logits in the POLICY row
        else:
            softmax_into(f, logits, prior, num, mem, legal, True)  # the root's prior: legal actions only
        if frac > 0.0 and has_noise and not gumbel_mode:
            dirichlet = f[lay.scratch + 3 * num:lay.scratch + 4 * num]
            dirichlet_row(noise[b], mem[legal:legal + num], dirichlet)
            for a in range(num):
                if mem[U(legal + a)] != 0:
                    f[U(prior + a)] = (1.0 - frac) * f[U(prior + a)] + frac * dirichlet[a]  # AlphaZero root noise
        f[U(nb + RAW_VALUE)] = root_value[b]
        f[U(nb + VALUE_SUM)] = root_value[b]
        f[U(nb + VISITS)] = 1.0
        _copy_latent(mem, lay, b, 0, STAGED, True)
        _select_and_gather(f, mem, lay, b, horizon)
    return OK


@njit(cache=True, error_model="numpy")
def _expand(f, mem, lay, b, node, reward, value, value_prefix):
    """Create node `node` of tree b under the pending (parent, action): header from the
    model's reward and value (EfficientZero: the edge reward is the prefix increase, or
    the prefix itself right after a reset of the LSTM segment). Its POLICY row holds the
    logits already; its other rows are written when it is opened."""
    nb = node_at(lay, b, node)
    parent = mem[U(lay.sel + b)]
    action = mem[U(lay.sel + lay.batch + b)]
    pb = node_at(lay, b, parent)
    f[U(row(lay, pb, CHILD) + action)] = node
    f[U(nb + VALUE_SUM)] = 0.0
    f[U(nb + VISITS)] = 0.0
    f[U(nb + PARENT)] = parent
    f[U(nb + ACTION)] = action
    f[U(nb + OPENED)] = 0.0
    f[U(nb + RAW_VALUE)] = value
    if value_prefix:
        f[U(nb + PREFIX)] = reward
        if mem[U(lay.sel + 2 * lay.batch + b)] != 0:
            f[U(nb + REWARD)] = reward
        else:
            f[U(nb + REWARD)] = reward - f[U(pb + PREFIX)]
    else:
        f[U(nb + PREFIX)] = 0.0
        f[U(nb + REWARD)] = reward


@njit(cache=True, error_model="numpy")
def expand_backup_select(mem, reward, value, logits, node, select_next):
    """One simulation's tail for all rows: expand node `node` under the pending (parent,
    action) with the model outputs (reward [B], value [B], logits [B, A]), back up its
    value, then (if select_next) select the next leaf and gather its parent's latent.
    Returns a status code (BAD_SHAPE before anything is written)."""
    lay = layout_of(mem)
    f = mem.view(np.float64)
    batch, num = lay.batch, lay.actions
    if reward.shape[0] != batch or value.shape[0] != batch or logits.shape != (batch, num):
        return BAD_SHAPE
    value_prefix = f[U(lay.params + P_VALUE_PREFIX)] != 0.0
    gamma_sign = f[U(lay.params + P_GAMMA_SIGN)]
    horizon = int(f[U(lay.params + P_HORIZON)])
    for b in range(batch):
        # A non-finite output aborts the search (the buffer needs no clean-up: nodes are
        # written when created), so rows are checked as they are expanded.
        if not (math.isfinite(reward[b]) and math.isfinite(value[b])):
            return NON_FINITE
        policy = row(lay, node_at(lay, b, node), POLICY)
        finite = True
        for a in range(num):
            x = logits[b, a]
            finite &= math.isfinite(x)
            f[U(policy + a)] = x
        if not finite:
            return NON_FINITE
        _expand(f, mem, lay, b, node, reward[b], value[b], value_prefix)
        _copy_latent(mem, lay, b, node, STAGED, True)
        _backup(f, lay, b, node, value[b], gamma_sign)
        if select_next:
            _select_and_gather(f, mem, lay, b, horizon)
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
def finish(mem, temperature, uniforms, visit_counts, policy, action, root_value, q_values):
    """Fill the outputs of every row: root child visits [B, A] int64, completed Q [B, A]
    float32, root value [B] float32, and the policy [B, A] float32 + action [B] int64.
    pUCT: the visit-count policy at `temperature`, the action drawn with uniforms [B]
    (argmax if temperature == 0). Gumbel: the improved policy softmax(logits +
    sigma(completed q)) and the action A_{n+1}: among the most-visited legal actions,
    argmax g + logits + sigma(completed q)."""
    lay = layout_of(mem)
    f = mem.view(np.float64)
    num = lay.actions
    probs, raw_q, sigma, improved = lay.scratch, lay.scratch + num, lay.scratch + 2 * num, lay.scratch + 3 * num
    gumbel_mode = f[U(lay.params + P_GUMBEL)] != 0.0
    for b in range(lay.batch):
        nb = node_at(lay, b, 0)
        legal, logits, gumbel = lay.legal + b * num, lay.logits + b * num, lay.gumbel + b * num
        completed_sigma(f, mem, lay, b, nb, logits, True)
        edge_n = row(lay, nb, EDGE_N)
        max_n = 0
        for a in range(num):
            q_values[b, a] = f[U(raw_q + a)]
            visit_counts[b, a] = int(f[U(edge_n + a)])
            max_n = max(max_n, visit_counts[b, a])
        root_value[b] = f[U(nb + VALUE_SUM)] / f[U(nb + VISITS)]
        if not gumbel_mode:
            uniform = uniforms[b] if uniforms.shape[0] > 0 else 0.0
            action[b] = _visit_policy_row(visit_counts[b], mem[legal:legal + num], temperature, uniform,
                                          f[probs:probs + num], policy[b])
            continue
        for a in range(num):
            f[U(probs + a)] = f[U(logits + a)] + f[U(sigma + a)]  # reuse probs as the improved logits
        softmax_into(f, probs, improved, num, mem, legal, True)
        best = -np.inf
        action[b] = 0
        for a in range(num):
            policy[b, a] = f[U(improved + a)]
            if mem[U(legal + a)] != 0 and visit_counts[b, a] == max_n:
                score = f[U(gumbel + a)] + f[U(logits + a)] + f[U(sigma + a)]
                if score > best:
                    best = score
                    action[b] = a
