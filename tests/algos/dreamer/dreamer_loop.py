"""A small in-process actor-learner loop for Dreamer tests (no Ray): vector env + policy +
SequenceWriter + uniform sampling + learner, following the runtime's step convention."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.dreamer import Dreamer, DreamerConfig
from wmdist.envs.config import EnvConfig
from wmdist.envs.vector import make_vector_env
from wmdist.replay.writer import SequenceWriter


def tiny_config(version: int = 3, **over) -> DreamerConfig:
    base = dict(version=version, deter=64, units=64, mlp_layers=1, stoch=8, classes=8 if version > 1 else 0, horizon=8)
    base.update(over)
    return DreamerConfig(**base)


def run_loop(env_id: str, cfg: DreamerConfig, env_steps: int, updates_every: int = 16, batch_size: int = 8,
             seq_len: int = 16, num_envs: int = 4, seed: int = 0, log=None,
             ) -> tuple[Dreamer, list[dict[str, float]], list[float]]:
    """Collect `env_steps` steps; after each `updates_every` env steps do one update.
    Returns (algo, per-update metrics, returns of the finished episodes)."""
    torch.manual_seed(seed)
    venv = make_vector_env(EnvConfig(id=env_id), num_envs, seed)
    algo = Dreamer(venv.spec, cfg, seed)
    policy, learner = algo.make_policy(), algo.make_learner()
    policy.set_weights(learner.get_weights(), 0)
    writer = SequenceWriter(algo.step_fields(), seq_len, seq_len // 2, num_envs)
    store: list[dict[str, np.ndarray]] = []
    rng = np.random.default_rng(seed)
    metrics: list[dict[str, float]] = []
    step = venv.reset()
    reward = np.zeros(num_envs, np.float32)
    episode_returns: list[float] = []
    running = np.zeros(num_envs)
    version, t = 0, 0
    zeros_action = np.zeros((num_envs, *venv.spec.action_shape), venv.spec.action_dtype)
    while t < env_steps:
        actions, extras = policy.act(step.obs, step.first, step.legal, step.to_play, explore=True)
        no = np.zeros(num_envs, bool)
        writer.add({"obs": step.obs, "action": actions, "reward": reward, "first": step.first, "last": no,
                    "terminal": no, **extras}, version)
        step = venv.step(actions)
        ended = step.terminated | step.truncated
        running += step.reward
        if ended.any():
            ids = np.flatnonzero(ended)
            writer.add({"obs": step.final_obs[ids], "action": zeros_action[ids], "reward": step.reward[ids],
                        "first": np.zeros(len(ids), bool), "last": np.ones(len(ids), bool),
                        "terminal": step.terminated[ids]}, version, env_ids=ids)
            episode_returns += [float(running[i]) for i in ids]
            running[ids] = 0.0
            if log is not None:
                log(t, episode_returns, metrics[-1] if metrics else {})
        reward = np.where(step.first, 0.0, step.reward).astype(np.float32)
        t += num_envs
        out = writer.pop()
        for i in range(len(out)):
            store.append({**{k: v[i] for k, v in out.data.items()}, "mask": out.mask[i]})
        if t % updates_every == 0 and len(store) >= batch_size:
            pick = rng.integers(0, len(store), batch_size)
            batch = {k: np.stack([store[j][k] for j in pick]) for k in store[0]}
            batch["is_weight"] = np.ones(batch_size, np.float32)
            metrics.append(learner.update(batch).metrics)
            version += 1
            policy.set_weights(learner.get_weights(), version)
    venv.close()
    algo.learner = learner  # type: ignore[attr-defined]
    return algo, metrics, episode_returns
