"""Small helpers every role's process uses to set itself up."""
from __future__ import annotations

import copy
import os

from wmdist.algos.base import Algorithm
from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec


def set_threads(n: int) -> None:
    """torch threads = this role's CPU share, so processes don't thrash a small machine.

    Also keeps freed memory mapped (`malloc.tune_malloc`): every role reallocates the same
    tensors each step. And flushes subnormal floats to zero on the CPU (FTZ/DAZ, as
    TensorFlow does by default): weight decay leaves trained weights and their gradients with
    subnormals, which x86 cores compute through slow microcode assists; the connect-four
    learner's update took 2x as long after 25 minutes of training (BENCHMARKS.md, subnormals)."""
    import torch

    from wmdist.runtime.malloc import tune_malloc

    tune_malloc()
    torch.set_flush_denormal(True)  # False where the CPU lacks the flags (then nothing changes)

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


def evaluation_config(cfg: RunConfig) -> RunConfig:
    """`cfg` as the evaluator plays: `eval.num_simulations`, when set, replaces the search's own
    count (a copy; the collectors' and learner's config is untouched)."""
    n = cfg.eval.num_simulations
    if not n:
        return cfg
    out = copy.deepcopy(cfg)
    out.algo.search.num_simulations = n
    return out


def device_for(gpus: float) -> str:
    import torch

    return "cuda" if gpus > 0 and torch.cuda.is_available() else "cpu"


def was_restarted() -> bool:
    """True in a process Ray started to replace a dead one (False outside a Ray actor)."""
    try:
        import warnings

        import ray

        if not ray.is_initialized():  # the local runner: asking would start a Ray instance
            return False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return bool(ray.get_runtime_context().was_current_actor_reconstructed)
    except Exception:  # noqa: BLE001 - not inside a Ray actor
        return False


def in_ray_actor() -> bool:
    """True inside a Ray actor's own process; False in the local runner, where every role shares
    the caller's process (a setting for one role's process must not change the others')."""
    try:
        import ray

        if not ray.is_initialized():
            return False
        return ray.get_runtime_context().get_actor_id() is not None
    except Exception:  # noqa: BLE001 - no Ray here
        return False


def process_tag() -> dict:
    """Who answered: the driver counts a restart when a new process answers for an actor, or
    when the first process it hears from is already a replacement (killed during start-up,
    its queued calls go to the replacement and no call fails)."""
    return {"pid": os.getpid(), "restarted": was_restarted()}
