"""World Models (Ha & Schmidhuber 2018): V (VAE), M (MDN-RNN), C (linear) trained by CMA-ES."""
from wmdist.algos.worldmodels.algo import WorldModels
from wmdist.algos.worldmodels.config import WorldModelsConfig

__all__ = ["WorldModels", "WorldModelsConfig"]
