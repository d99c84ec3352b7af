"""MuZero and MuZero Reanalyze (`algo.name: muzero`)."""
from wmdist.algos.muzero.algorithm import MuZero
from wmdist.algos.muzero.config import MuZeroConfig

__all__ = ["MuZero", "MuZeroConfig"]
