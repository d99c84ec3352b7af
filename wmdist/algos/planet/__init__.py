"""PlaNet: the RSSM world model (shared with Dreamer, `wmdist.nets`) and CEM planning (`wmdist.search.cem`)."""
from wmdist.algos.planet.algo import PlaNet
from wmdist.algos.planet.config import PlaNetConfig

__all__ = ["PlaNet", "PlaNetConfig"]
