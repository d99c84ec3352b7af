"""Dreamer V1, V2 and V3: one RSSM, the version is configuration (see config.py)."""
from wmdist.algos.dreamer.algo import Dreamer
from wmdist.algos.dreamer.config import DreamerConfig

__all__ = ["Dreamer", "DreamerConfig"]
