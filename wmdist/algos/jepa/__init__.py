"""JEPA with SIGReg (LeWorldModel): a reconstruction-free world model that plans to goal images."""
from wmdist.algos.jepa.algo import Jepa
from wmdist.algos.jepa.config import JepaConfig

__all__ = ["Jepa", "JepaConfig"]
