"""An evaluation actor of the pool (role `wm_eval`): scores shares of a generation's candidates.

It holds the model the learner froze for the controller search (M and the dream's start
latents; V too for real rollouts), cached under the learner's `model_id`; a fresh or restarted
process has none and answers `missing_model`, and the learner sends it. Real rollouts run in
`real_envs` envs this actor builds from the run's env section, stepped in lockstep.
"""
from __future__ import annotations

import os
import time
from typing import Any

import numpy as np
import torch

from wmdist.algos.worldmodels.config import WorldModelsConfig
from wmdist.algos.worldmodels.models import build_rnn, build_vae, load_numpy
from wmdist.algos.worldmodels.rollout import dream_fitness, real_returns
from wmdist.envs.spec import EnvSpec


class EvalWorker:
    def __init__(self, run_config: Any, spec: EnvSpec, index: int, threads: int = 1,
                 algo_config: WorldModelsConfig | None = None) -> None:
        if threads > 0:
            torch.set_num_threads(threads)
        torch.set_flush_denormal(True)  # as every role (wmdist.runtime.roles.setup.set_threads)
        self.run_config, self.spec, self.index = run_config, spec, index
        self.cfg: WorldModelsConfig = algo_config if algo_config is not None else run_config.algo
        self.model_id = -1
        self.rnn = build_rnn(self.cfg, spec).eval()
        self.vae = None
        self.bank_mu = self.bank_logvar = None
        self.envs: list[Any] = []  # real rollouts' envs, stepped in lockstep

    def load_model(self, model_id: int, weights: dict[str, np.ndarray]) -> bool:
        load_numpy(self.rnn, weights, "rnn")
        if any(k.startswith("vae.") for k in weights):
            self.vae = build_vae(self.cfg, self.spec).eval()
            load_numpy(self.vae, weights, "vae")
        self.bank_mu = torch.as_tensor(np.asarray(weights["bank_mu"], np.float32))  # [K, Z]
        self.bank_logvar = torch.as_tensor(np.asarray(weights["bank_logvar"], np.float32))
        self.model_id = int(model_id)
        return True

    def evaluate(self, model_id: int, params: np.ndarray, seeds: np.ndarray, mode: str) -> dict:
        """Fitness of candidates params [n, P], each over the rollouts `seeds` [R]."""
        if int(model_id) != self.model_id:
            return {"missing_model": True, "pid": os.getpid()}
        t0 = time.monotonic()
        x = torch.as_tensor(np.asarray(params, np.float32))
        if mode == "dream":
            fitness = self._dream(x, np.asarray(seeds))
        elif mode == "real":
            fitness = self._real(x, np.asarray(seeds))
        else:
            raise ValueError(f"unknown evaluation mode {mode!r}")
        return {"fitness": fitness.tolist(), "busy_seconds": time.monotonic() - t0, "pid": os.getpid()}

    def _dream(self, x: torch.Tensor, seeds: np.ndarray) -> np.ndarray:
        gen = torch.Generator().manual_seed(int(seeds[0]))
        k = len(self.bank_mu)
        starts = torch.as_tensor(seeds % k)  # [R] one start latent per rollout seed
        eps = torch.randn((len(seeds), self.cfg.z_dim), generator=torch.Generator().manual_seed(int(seeds.sum() % 2**31)))
        z0 = self.bank_mu[starts] + torch.exp(0.5 * self.bank_logvar[starts]) * eps  # [R, Z]
        z0 = z0[None].expand(x.shape[0], -1, -1).contiguous()  # [n, R, Z]
        return dream_fitness(x, z0, self.rnn, self.spec, self.cfg.temperature, self.cfg.dream_max_steps, gen)

    def _real(self, x: torch.Tensor, seeds: np.ndarray) -> np.ndarray:
        if self.vae is None:
            raise RuntimeError("real rollouts need V: the model sent had none")
        jobs = [(i, int(s)) for i in range(x.shape[0]) for s in seeds]  # (candidate, seed) episodes
        width = max(1, min(self.cfg.real_envs, len(jobs)))
        from wmdist.envs.factory import make_env

        while len(self.envs) < width:
            self.envs.append(make_env(self.run_config.env, seed=1000 * self.index + len(self.envs)))
        cap = self.cfg.real_max_steps or None
        returns = np.zeros(len(jobs))
        for lo in range(0, len(jobs), width):
            chunk = jobs[lo: lo + width]
            returns[lo: lo + len(chunk)] = real_returns(
                x[[i for i, _ in chunk]], self.envs, self.vae, self.rnn, self.spec, np.array([s for _, s in chunk]), cap,
                self.cfg.real_patience)
        return returns.reshape(x.shape[0], len(seeds)).mean(1)

    def ping(self) -> bool:
        return True

    def pid(self) -> int:
        return os.getpid()

    def node_id(self) -> str:
        """The Ray node this actor runs on (placement checks)."""
        import ray

        return ray.get_runtime_context().get_node_id()
