"""`wmdist dream RUN --check` for World Models: the published controller and simple fixed
policies scored in M's dream and in the real env, side by side.

A controller trained in the dream is only as good as M is where the controller goes. A policy
that M rates far above the real game is what CMA-ES will find and exploit (sessions 28-29 on
Take Cover: an agent standing still lived 674 steps in one M's dream and ~110 in the game). The
fixed policies are controllers too (W = 0, b picks the action), so both columns come from the
evaluation actor's own scoring code, on the run's temperature, caps and dream starts.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from wmdist.algos.worldmodels.controller import num_params
from wmdist.envs.spec import EnvSpec

MODEL_ID = 1  # the one model the local evaluation actor holds


def fixed_controllers(spec: EnvSpec, z_dim: int, hidden: int, reads_h: bool = True) -> dict[str, np.ndarray]:
    """Controllers [P] that ignore [z, h]: each discrete action always, or the middle of every
    continuous action's range (tanh(0))."""
    p, a = num_params(spec, z_dim, hidden, reads_h), spec.action_dim
    if not spec.discrete:
        return {"zero action": np.zeros(p, np.float32)}
    out = {}
    for i in range(spec.num_actions):
        x = np.zeros(p, np.float32)
        x[p - a + i] = 1.0  # the bias b [A] is last: argmax picks action i
        out[f"always action {i}"] = x
    return out


def dream_check(run_config: Any, spec: EnvSpec, weights: Mapping[str, np.ndarray], learner_state: Mapping[str, Any],
                rollouts: int = 64, episodes: int = 5, seed: int = 0) -> list[dict[str, float | str]]:
    """Rows {policy, dream, real}: mean dream score (steps survived) over `rollouts` dreams from
    the run's start latents, and mean real return over `episodes` greedy episodes."""
    from wmdist.algos.worldmodels.worker import EvalWorker

    if len(np.asarray(learner_state.get("bank_mu", ()))) == 0:
        raise ValueError("the run has no dream starts yet: M has not trained (algo.rnn_updates)")
    cfg = run_config.algo
    worker = EvalWorker(run_config, spec, index=0, threads=0, algo_config=cfg)
    model = {k: np.asarray(v) for k, v in weights.items() if k.startswith(("rnn.", "vae."))}
    model.update(bank_mu=np.asarray(learner_state["bank_mu"]), bank_logvar=np.asarray(learner_state["bank_logvar"]))
    worker.load_model(MODEL_ID, model)
    policies = {}
    if float(np.asarray(weights.get("has_controller", 0.0))) > 0:
        policies["controller"] = np.asarray(weights["controller"], np.float32)
    policies.update(fixed_controllers(spec, cfg.z_dim, cfg.rnn_hidden, cfg.controller_h))
    x = np.stack(list(policies.values()))  # [N, P]
    dream_seeds = np.random.default_rng([seed, 1]).integers(0, 2**31 - 1, size=rollouts)  # [R]
    dream = worker.evaluate(MODEL_ID, x, dream_seeds, "dream")["fitness"]
    real = worker.evaluate(MODEL_ID, x, np.arange(episodes) + 10_000 * (seed + 1), "real")["fitness"]
    return [{"policy": name, "dream": float(d), "real": float(r)} for name, d, r in zip(policies, dream, real)]

