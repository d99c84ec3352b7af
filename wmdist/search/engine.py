"""The batched search loop: validation, one recurrent_fn call + one kernel call per
simulation, outputs. The search buffer comes from a per-thread cache (`workspace.py`)."""
from __future__ import annotations

from typing import Any

import numpy as np

from wmdist.search import kernels as K
from wmdist.search import layout as L
from wmdist.search.api import RecurrentFn, SearchConfig, SearchOutput
from wmdist.search.noise import considered_visit_table, draw_root_noise
from wmdist.search.workspace import Workspace, acquire


def _as_float(x: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    """x as a C-contiguous float64 array of `shape`, or a ValueError naming `what`."""
    if np.shape(x) != shape:
        raise ValueError(f"{what} must have shape {shape}, got {np.shape(x)}")
    return np.ascontiguousarray(x, dtype=np.float64)


def _write_params(p: np.ndarray, config: SearchConfig, two_player: bool, add_noise: bool) -> None:
    """The params region (layout.P_*), in one numpy call."""
    use_dirichlet = add_noise and not config.gumbel
    p[:L.NUM_PARAMS] = (
        config.c1,  # P_C1
        config.c2,  # P_C2
        config.discount * (-1.0 if two_player else 1.0),  # P_GAMMA_SIGN
        1.0 if config.unvisited_value == "parent" else 0.0,  # P_UNVISITED_PARENT
        1.0 if config.gumbel else 0.0,  # P_GUMBEL
        config.gumbel_c_visit,  # P_C_VISIT
        config.gumbel_c_scale,  # P_C_SCALE
        1.0 if config.value_prefix else 0.0,  # P_VALUE_PREFIX
        config.lstm_horizon,  # P_HORIZON
        config.gumbel_max_considered,  # P_MAX_CONSIDERED
        config.dirichlet_fraction if use_dirichlet else 0.0,  # P_NOISE_FRACTION
    )


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


def _check_inputs(root_logits: Any, root_value: Any, legal: Any, to_play: Any, temperature: float):
    """Shapes and kinds of the inputs (finiteness and 'a legal action per row' are checked
    by the init kernel); returns (logits [B, A], value [B], legal [B, A]) as numpy arrays."""
    logits = _as_array(root_logits)
    if logits.ndim != 2 or logits.shape[0] < 1 or logits.shape[1] < 1:
        raise ValueError(f"root_logits must have shape [B, A] with B, A >= 1, got {logits.shape}")
    batch, num_actions = logits.shape
    value = _as_array(root_value)
    if value.shape != (batch,):
        raise ValueError(f"root_value must have shape {(batch,)}, got {value.shape}")
    legal = np.asarray(legal)
    if legal.shape != (batch, num_actions) or legal.dtype != np.bool_:
        raise ValueError(f"legal must be a bool array of shape {(batch, num_actions)}, got {legal.dtype} {legal.shape}")
    if to_play is not None and np.shape(to_play) != (batch,):
        raise ValueError(f"to_play must have shape ({batch},), got {np.shape(to_play)}")
    if not temperature >= 0:
        raise ValueError(f"temperature must be >= 0, got {temperature}")
    return logits, value, legal


def _as_array(x: Any) -> np.ndarray:
    """x itself if it is a float32/float64 numpy array (the kernels read both), else float64."""
    if type(x) is np.ndarray and x.dtype.char in "fd":
        return x
    return np.asarray(x, dtype=np.float64)


def _model_outputs(out: Any, batch: int, num_actions: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """recurrent_fn's (reward, value, logits, latents) with the arrays as the kernel reads
    them: float32/float64 numpy arrays of the right rank (shapes are checked in the kernel)."""
    reward, value, logits, latents = out
    if not (type(reward) is np.ndarray and reward.ndim == 1 and reward.dtype.char in "fd"):
        reward = _as_float(reward, (batch,), "recurrent_fn reward")
    if not (type(value) is np.ndarray and value.ndim == 1 and value.dtype.char in "fd"):
        value = _as_float(value, (batch,), "recurrent_fn value")
    if not (type(logits) is np.ndarray and logits.ndim == 2 and logits.dtype.char in "fd"):
        logits = _as_float(logits, (batch, num_actions), "recurrent_fn logits")
    return reward, value, logits, latents


def _raise_for(status: int, simulation: int, reward: np.ndarray, value: np.ndarray, logits: np.ndarray,
               batch: int, num_actions: int) -> None:
    """The ValueError for a kernel's failure status on recurrent_fn's outputs."""
    if status == L.BAD_SHAPE:
        for x, shape, what in ((reward, (batch,), "reward"), (value, (batch,), "value"),
                               (logits, (batch, num_actions), "logits")):
            _as_float(x, shape, f"recurrent_fn {what}")
    raise ValueError(f"recurrent_fn returned non-finite reward, value or logits at simulation {simulation}")


_NO_DRAWS = np.zeros((0, 0))
_FLOAT_DTYPES = (np.dtype(np.float64), np.dtype(np.float32))  # `in` hits by identity first: cheaper than .char
_NO_UNIFORMS = np.zeros(0)


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
    logits, value, legal = _check_inputs(root_logits, root_value, legal, to_play, temperature)
    batch, num_actions = logits.shape
    sims = config.num_simulations
    draws = draw_root_noise(rng, batch, num_actions, config.dirichlet_alpha, config.gumbel, add_noise)
    table = considered_visit_table(config.gumbel_max_considered, sims)
    ws = acquire(batch, num_actions, table, root_latent)
    try:
        _write_params(ws.params, config, two_player, add_noise)
        _run_simulations(ws, logits, value, legal, _NO_DRAWS if draws is None else draws, recurrent_fn,
                         sims, config.value_prefix)
        visit_counts = np.empty((batch, num_actions), dtype=np.int64)
        policy = np.empty((batch, num_actions), dtype=np.float32)
        action = np.empty(batch, dtype=np.int64)
        search_value = np.empty(batch, dtype=np.float32)
        q_values = np.empty((batch, num_actions), dtype=np.float32)
        sampled = not config.gumbel and temperature > 0
        uniforms = rng.random(batch) if sampled else _NO_UNIFORMS  # the draws of sample_actions
        K.finish(ws.mem, float(temperature), uniforms, visit_counts, policy, action, search_value, q_values)
    finally:
        ws.release()
    return SearchOutput(visit_counts=visit_counts, policy=policy, action=action, root_value=search_value,
                        q_values=q_values)


def _run_simulations(ws: Workspace, logits: np.ndarray, value: np.ndarray, legal: np.ndarray, draws: np.ndarray,
                     recurrent_fn: RecurrentFn, sims: int, value_prefix: bool) -> None:
    """Expand the roots, then `sims` x (one recurrent_fn call + one kernel call)."""
    mem, sel = ws.mem, ws.sel
    status = K.init_roots(mem, logits, value, legal, draws)
    if status == L.NO_LEGAL:
        raise ValueError("every root needs at least one legal action")
    if status != L.OK:
        raise ValueError("root_logits and root_value must be finite")
    batch, num_actions = logits.shape
    actions = sel[L.SEL_ACTION]  # view: the kernels update it in place
    reset = sel[L.SEL_RESET]
    # Hot loop: everything bound to locals, no calls but the model, the staging copy and
    # the kernel; the kernel checks shapes and finiteness, the loop only that the outputs
    # are float arrays of the right rank (anything else goes through _model_outputs).
    step, outputs, ndarray, floats = K.expand_backup_select, _model_outputs, np.ndarray, _FLOAT_DTYPES
    stage, latents_in = ws.latents.stage, ws.latents.gathered_latents
    for s in range(sims):
        if value_prefix:
            out = recurrent_fn(latents_in, actions, reset != 0)
        else:
            out = recurrent_fn(latents_in, actions)
        reward, leaf_value, leaf_logits, next_latents = out
        if not (type(reward) is ndarray and type(leaf_value) is ndarray and type(leaf_logits) is ndarray
                and reward.ndim == 1 and leaf_value.ndim == 1 and leaf_logits.ndim == 2
                and reward.dtype in floats and leaf_value.dtype in floats and leaf_logits.dtype in floats):
            reward, leaf_value, leaf_logits, next_latents = outputs(out, batch, num_actions)
        stage(next_latents)
        status = step(mem, reward, leaf_value, leaf_logits, s + 1, s + 1 < sims)
        if status != L.OK:
            _raise_for(status, s, reward, leaf_value, leaf_logits, batch, num_actions)
