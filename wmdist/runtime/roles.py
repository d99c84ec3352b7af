"""Small helpers every role's process uses to set itself up."""
from __future__ import annotations

from wmdist.algos.base import Algorithm
from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec


def set_threads(n: int) -> None:
    """torch threads = this role's CPU share, so processes don't thrash a small machine."""
    import torch

    torch.set_num_threads(max(1, int(n)))
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # already set in this process
        pass


def build_algorithm(cfg: RunConfig, spec: EnvSpec, seed: int) -> Algorithm:
    from wmdist.algos.registry import resolve

    algo = resolve(cfg.algo_name)(spec, cfg.algo, seed=seed)
    algo.validate()
    return algo


def device_for(gpus: float) -> str:
    import torch

    return "cuda" if gpus > 0 and torch.cuda.is_available() else "cpu"
