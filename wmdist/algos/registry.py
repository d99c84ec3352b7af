"""Algorithm names -> classes, imported lazily so a config loads without torch models."""
from __future__ import annotations

import importlib

from wmdist.algos.base import Algorithm

ALGORITHMS: dict[str, str] = {
    "muzero": "wmdist.algos.muzero:MuZero",
    "dreamer": "wmdist.algos.dreamer:Dreamer",
    "planet": "wmdist.algos.planet:PlaNet",
    "efficientzero": "wmdist.algos.efficientzero:EfficientZero",
    "worldmodels": "wmdist.algos.worldmodels:WorldModels",
    "jepa": "wmdist.algos.jepa:Jepa",
}


def resolve(name: str) -> type[Algorithm]:
    """A registered name, or `package.module:Class` for an algorithm outside wmdist."""
    from wmdist.config.errors import ConfigError, closest

    target = ALGORITHMS.get(name, name if ":" in name else None)
    if target is None:
        raise ConfigError(f"unknown algorithm {name!r}{closest(name, ALGORITHMS)}; known: {', '.join(sorted(ALGORITHMS))}")
    module_name, _, cls_name = target.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), cls_name)
    except (ImportError, AttributeError) as err:
        raise ConfigError(f"algorithm {name!r} cannot be loaded from {target}: {err}") from None
    if not (isinstance(cls, type) and issubclass(cls, Algorithm)):
        raise ConfigError(f"algorithm {name!r}: {target} is not a wmdist Algorithm")
    return cls
