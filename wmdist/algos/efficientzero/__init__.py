"""EfficientZero (`algo.name: efficientzero`): MuZero plus a value prefix, a self-supervised
consistency loss and an off-policy correction of reanalyzed value targets."""
from wmdist.algos.efficientzero.algorithm import EfficientZero
from wmdist.algos.efficientzero.config import EfficientZeroConfig

__all__ = ["EfficientZero", "EfficientZeroConfig"]
