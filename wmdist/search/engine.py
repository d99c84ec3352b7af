"""The batched search loop: validation, tree allocation, one recurrent_fn call per simulation."""
from __future__ import annotations

from typing import Any

import numpy as np

from wmdist.search import kernels as K
from wmdist.search import layout as L
from wmdist.search.api import RecurrentFn, SearchConfig, SearchOutput
from wmdist.search.latents import LatentStore
from wmdist.search.noise import considered_visit_table, sample_root_noise


_F64 = np.dtype(np.float64)


def _as_float(x: Any, shape: tuple[int, ...], what: str, out: np.ndarray | None = None) -> np.ndarray:
    """x as a C-contiguous float64 array of `shape`: x itself if it already is one, else a
    converted copy (into `out` if given: no allocation per simulation)."""
    if type(x) is np.ndarray and x.dtype is _F64 and x.shape == shape and x.flags.c_contiguous:
        return x
    if np.shape(x) != shape:
        raise ValueError(f"{what} must have shape {shape}, got {np.shape(x)}")
    if out is None:
        return np.ascontiguousarray(x, dtype=np.float64)
    np.copyto(out, x, casting="same_kind")
    return out


def _params(config: SearchConfig, two_player: bool, add_noise: bool) -> np.ndarray:
    p = np.zeros(L.NUM_PARAMS)
    p[L.P_C1] = config.c1
    p[L.P_C2] = config.c2
    p[L.P_GAMMA_SIGN] = config.discount * (-1.0 if two_player else 1.0)
    p[L.P_UNVISITED_PARENT] = 1.0 if config.unvisited_value == "parent" else 0.0
    p[L.P_GUMBEL] = 1.0 if config.gumbel else 0.0
    p[L.P_C_VISIT] = config.gumbel_c_visit
    p[L.P_C_SCALE] = config.gumbel_c_scale
    p[L.P_VALUE_PREFIX] = 1.0 if config.value_prefix else 0.0
    p[L.P_HORIZON] = config.lstm_horizon
    p[L.P_MAX_CONSIDERED] = config.gumbel_max_considered
    use_dirichlet = add_noise and not config.gumbel
    p[L.P_NOISE_FRACTION] = config.dirichlet_fraction if use_dirichlet else 0.0
    return p


def visit_policy(visit_counts: np.ndarray, legal: np.ndarray, temperature: float) -> np.ndarray:
    """[B, A] policy proportional to N(a)^(1/T) over legal actions; one-hot argmax if T == 0."""
    counts = visit_counts.astype(np.float64) * legal
    if temperature == 0:
        policy = np.zeros_like(counts)
        policy[np.arange(len(counts)), counts.argmax(axis=1)] = 1.0
        return policy
    # (N / max N)^(1/T) stays in [0, 1]: no overflow for small T.
    scaled = (counts / counts.max(axis=1, keepdims=True)) ** (1.0 / temperature)
    return scaled / scaled.sum(axis=1, keepdims=True)


def sample_actions(policy: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """[B] one draw per row from policy [B, A]; never picks a zero-probability action."""
    cdf = np.cumsum(policy, axis=1)
    x = (1.0 - rng.random(len(policy))) * cdf[:, -1]  # in (0, total]
    return np.minimum((cdf < x[:, None]).sum(axis=1), policy.shape[1] - 1)


def _check_inputs(root_logits: np.ndarray, root_value: Any, legal: Any, to_play: Any, temperature: float):
    if root_logits.ndim != 2 or root_logits.shape[0] < 1 or root_logits.shape[1] < 1:
        raise ValueError(f"root_logits must have shape [B, A] with B, A >= 1, got {root_logits.shape}")
    batch, num_actions = root_logits.shape
    value = _as_float(root_value, (batch,), "root_value")
    legal = np.asarray(legal)
    if legal.shape != (batch, num_actions) or legal.dtype != np.bool_:
        raise ValueError(f"legal must be a bool array of shape {(batch, num_actions)}, got {legal.dtype} {legal.shape}")
    if not legal.any(axis=1).all():
        raise ValueError("every root needs at least one legal action")
    if to_play is not None and np.shape(to_play) != (batch,):
        raise ValueError(f"to_play must have shape ({batch},), got {np.shape(to_play)}")
    if not temperature >= 0:
        raise ValueError(f"temperature must be >= 0, got {temperature}")
    return value, np.ascontiguousarray(legal)


def run_search(
    root_latent: Any,
    root_logits: np.ndarray,
    root_value: np.ndarray,
    legal: np.ndarray,
    to_play: np.ndarray | None,
    recurrent_fn: RecurrentFn,
    config: SearchConfig,
    rng: np.random.Generator,
    temperature: float = 1.0,
    add_noise: bool = True,
    two_player: bool = False,
) -> SearchOutput:
    """See `wmdist.search.api.search`."""
    logits = np.ascontiguousarray(np.asarray(root_logits, dtype=np.float64))
    value, legal = _check_inputs(logits, root_value, legal, to_play, temperature)
    batch, num_actions = logits.shape
    sims = config.num_simulations
    num_nodes = sims + 1
    dirichlet, gumbel = sample_root_noise(rng, legal, config.dirichlet_alpha, config.gumbel, add_noise)

    nodes_f = np.zeros((batch, num_nodes, 4))
    nodes_i = np.zeros((batch, num_nodes, 5), dtype=np.int32)
    children = np.full((batch, num_nodes, num_actions), -1, dtype=np.int32)
    edges_f = np.zeros((batch, num_nodes, 4, num_actions))
    minmax = np.empty((batch, 2))
    minmax[:, 0], minmax[:, 1] = np.inf, -np.inf
    table = considered_visit_table(config.gumbel_max_considered, sims)
    params = _params(config, two_player, add_noise)
    sel = np.zeros((3, batch), dtype=np.int64)  # pending leaf per row: parent, action, reset
    store = LatentStore(root_latent, batch, num_nodes)
    tree = (nodes_f, nodes_i, children, edges_f, legal, gumbel, minmax, table, params)

    status = K.init_roots(*tree, logits, value, dirichlet, store.store, store.staged, store.gathered, sel)
    if status != L.OK:
        raise ValueError("root_logits and root_value must be finite")
    actions = sel[L.SEL_ACTION]  # view: the kernels update it in place
    reset = sel[L.SEL_RESET]
    # Hot loop: one model call + one kernel call per simulation; names bound locally.
    step, stage, latents_in = K.expand_backup_select, store.stage, store.gathered_latents
    row_shape, logits_shape = (batch,), (batch, num_actions)
    reward_buf, value_buf, logits_buf = np.empty(batch), np.empty(batch), np.empty(logits_shape)
    for s in range(sims):
        if config.value_prefix:
            out = recurrent_fn(latents_in, actions, reset.astype(bool))
        else:
            out = recurrent_fn(latents_in, actions)
        reward, leaf_value, leaf_logits, next_latents = out
        reward = _as_float(reward, row_shape, "recurrent_fn reward", reward_buf)
        leaf_value = _as_float(leaf_value, row_shape, "recurrent_fn value", value_buf)
        leaf_logits = _as_float(leaf_logits, logits_shape, "recurrent_fn logits", logits_buf)
        stage(next_latents)
        status = step(*tree, s + 1, reward, leaf_value, leaf_logits, store.store, store.staged, store.gathered,
                      sel, s + 1 < sims)
        if status != L.OK:
            raise ValueError(f"recurrent_fn returned non-finite reward, value or logits at simulation {s}")

    visit_counts = np.zeros((batch, num_actions), dtype=np.int64)
    q_values = np.zeros((batch, num_actions))
    improved = np.zeros((batch, num_actions))
    gumbel_action = np.zeros(batch, dtype=np.int64)
    search_value = np.zeros(batch)
    K.root_statistics(nodes_f, nodes_i, children, edges_f, legal, gumbel, params,
                      visit_counts, q_values, improved, gumbel_action, search_value)
    if config.gumbel:
        policy, action = improved, gumbel_action
    else:
        policy = visit_policy(visit_counts, legal, temperature)
        action = policy.argmax(axis=1) if temperature == 0 else sample_actions(policy, rng)
    return SearchOutput(
        visit_counts=visit_counts,
        policy=policy.astype(np.float32),
        action=action.astype(np.int64),
        root_value=search_value.astype(np.float32),
        q_values=q_values.astype(np.float32),
    )
