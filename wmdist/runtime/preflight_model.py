"""The model-size check `wmdist train` makes before anything starts.

A size field set far too large (`algo.value_support=1e8`, `algo.deter=1e6`) builds a model
that cannot fit: without this check the run starts, and the learner dies minutes later in an
allocation failure or Ray's memory monitor kills it, and perhaps other runs on the node with
it. The check builds the learner and one policy on torch's `meta` device, which records
shapes and allocates nothing, and counts what the run will hold at least: the learner's
trainable weights four times (weight, gradient, Adam's two moments), its frozen ones and
buffers once, and one policy per collector, evaluator and reanalyzer. Activations are not
counted, so a model refused here can never fit, and one that passes may still not.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator

import torch
from torch import nn

from wmdist.config.errors import ConfigError, first_line
from wmdist.runtime.preflight_memory import format_bytes, node_memory_bytes

TRAINED_COPIES = 4  # weight, gradient, Adam's first and second moments
_DEPTH = 4  # how deep to look through a learner's attributes for its networks


@dataclass
class ModelSize:
    bytes_held: int  # what the object holds at least, per the rule in the module docstring
    params: int  # parameters, each counted once
    largest: str  # the largest tensor: "path [shape]"


def _modules(obj: Any, path: str, seen: set[int], depth: int = 0) -> Iterator[tuple[str, nn.Module]]:
    """The nn.Modules an object holds in its attributes, lists and dicts, with their paths."""
    if id(obj) in seen or depth > _DEPTH:
        return
    seen.add(id(obj))
    if isinstance(obj, nn.Module):
        yield path, obj
        return
    if isinstance(obj, dict):
        items = [(str(k), v) for k, v in obj.items()]
    elif isinstance(obj, (list, tuple)):
        items = [(str(i), v) for i, v in enumerate(obj)]
    elif hasattr(obj, "__dict__") and type(obj).__module__.startswith("wmdist"):
        items = list(vars(obj).items())
    else:
        return
    for name, value in items:
        yield from _modules(value, f"{path}.{name}" if path else name, seen, depth + 1)


def model_size(obj: Any, trained_copies: int = TRAINED_COPIES) -> ModelSize:
    """What a learner (trained_copies = 4) or a policy (1) holds; every tensor counted once."""
    held, params, largest, largest_n = 0, 0, "", -1
    counted: set[int] = set()
    for path, module in _modules(obj, "", set()):
        tensors = [(n, t, True) for n, t in module.named_parameters()] + [(n, t, False) for n, t in module.named_buffers()]
        for name, t, is_param in tensors:
            if id(t) in counted:
                continue
            counted.add(id(t))
            nbytes = t.numel() * t.element_size()
            held += nbytes * (trained_copies if is_param and t.requires_grad else 1)
            if is_param:
                params += t.numel()
            if t.numel() > largest_n:
                largest_n, largest = t.numel(), f"{path}.{name} {list(t.shape)}"
    return ModelSize(held, params, largest)


def measure(algo: Any) -> tuple[ModelSize, ModelSize]:
    """The learner's and one policy's sizes, built on the meta device: layers that create their
    weights on the default device before moving them must not allocate them either."""
    with torch.device("meta"):
        return model_size(algo.make_learner("meta")), model_size(algo.make_policy("meta"), trained_copies=1)


def policy_copies(cfg: Any) -> int:
    """Models held besides the learner's: one per collector, evaluator and reanalyzer."""
    return cfg.actors.num + (1 if cfg.eval.enabled else 0) + cfg.reanalyze.num


def check_model(cfg: Any, algo: Any, memory: int | None = None) -> None:
    """Raise ConfigError if the model `cfg` builds cannot fit in this machine's memory.

    A run that joins a cluster (`ray.address`) is not judged by this machine. A model that
    cannot be built on the meta device is not judged either (the run's own start reports it)."""
    if cfg.ray.address:
        return
    memory = node_memory_bytes() if memory is None else memory
    if not memory:
        return
    host, what = algo.host_memory()  # allocated for real while the learner is built: refused first
    if host > memory:
        raise ConfigError(f"{what} needs {format_bytes(host)}, more than this machine's memory ({format_bytes(memory)})")
    try:
        learner, policy = measure(algo)
    except RuntimeError as err:
        if "overflow" in str(err):  # a tensor with more elements than torch can index
            raise ConfigError(f"the model this config builds is too large for torch to size ({first_line(err)}); "
                              f"lower the algo.* size that makes it") from None
        return  # an op the meta device lacks: leave it to the run itself
    except Exception:  # noqa: BLE001 - as above
        return
    copies = policy_copies(cfg)
    need = host + learner.bytes_held + copies * policy.bytes_held
    if need > memory:
        raise ConfigError(
            f"the model this config builds has {learner.params:,} parameters: the learner's weights, gradients and "
            f"Adam moments and {copies} policy copies need at least {format_bytes(need)}, more than this machine's memory "
            f"({format_bytes(memory)}); its largest tensor is {learner.largest}: lower the algo.* size that makes it")
