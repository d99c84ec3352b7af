"""A RunConfig for in-process algorithm tests: the local runner's collector and replay with
one collector stepping `num_envs` envs one step per segment, no rate limit, uniform sampling."""
from __future__ import annotations

import dataclasses

from wmdist.algos.base import Algorithm
from wmdist.config.schema import RunConfig
from wmdist.envs.config import EnvConfig


def local_run_config(algo: Algorithm, env_cfg: EnvConfig, num_envs: int, seq_len: int, overlap: int,
                     seed: int = 0, batch_size: int = 8) -> RunConfig:
    cfg = RunConfig()
    cfg.env = env_cfg
    cfg.algo, cfg.algo_name = algo.config, algo.name
    cfg.run = dataclasses.replace(cfg.run, seed=seed)
    cfg.ray = dataclasses.replace(cfg.ray, local=True)
    cfg.actors = dataclasses.replace(cfg.actors, num=1, envs_per_actor=num_envs, segment_steps=1,
                                     warmup_random_steps=0, insert_timeout=0.0)
    cfg.replay = dataclasses.replace(cfg.replay, seq_len=seq_len, overlap=overlap, min_size=0, samples_per_insert=0,
                                     capacity_steps=max(200_000, 4 * seq_len), shards=1, sampler="uniform",
                                     seed=seed, max_policy_lag=0)
    cfg.learner = dataclasses.replace(cfg.learner, batch_size=batch_size)
    cfg.eval = dataclasses.replace(cfg.eval, every_seconds=0, every_env_steps=0)
    cfg.metrics = dataclasses.replace(cfg.metrics, enabled=False, tensorboard=False)
    return cfg
