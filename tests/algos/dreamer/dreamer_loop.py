"""Dreamer test helpers: a tiny config, and an in-process loop over the local runner's own
collector, replay and learner (no Ray; the runtime's step convention by construction)."""
from __future__ import annotations

import torch

from tests.algos.local_config import local_run_config
from wmdist.algos.dreamer import Dreamer, DreamerConfig
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec
from wmdist.runtime.local import LocalSession


def tiny_config(version: int = 3, **over) -> DreamerConfig:
    base = dict(version=version, deter=64, units=64, mlp_layers=1, stoch=8, classes=8 if version > 1 else 0, horizon=8)
    base.update(over)
    return DreamerConfig(**base)


def run_loop(env_id: str, cfg: DreamerConfig, env_steps: int, updates_every: int = 16, batch_size: int = 8,
             seq_len: int = 16, num_envs: int = 4, seed: int = 0,
             ) -> tuple[Dreamer, list[dict[str, float]], list[float]]:
    """Collect `env_steps` steps with the runtime's own collector and replay (the local
    runner's `LocalSession`); after each `updates_every` env steps do one update.
    Returns (algo, per-update metrics, returns of the finished episodes)."""
    torch.manual_seed(seed)
    env_cfg = EnvConfig(id=env_id)
    algo = Dreamer(env_spec(env_cfg), cfg, seed)
    session = LocalSession(local_run_config(algo, env_cfg, num_envs, seq_len, seq_len // 2, seed, batch_size))
    metrics: list[dict[str, float]] = []
    try:
        while session.env_steps < env_steps:
            session.collect(1)
            if session.env_steps % updates_every == 0 and session.stored_count() >= batch_size:
                metrics += session.train(1, batch_size)
        algo.learner = session.learner  # type: ignore[attr-defined]
        return algo, metrics, list(session.returns)
    finally:
        session.close()
