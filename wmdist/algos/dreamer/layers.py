"""The latent layers moved to `wmdist.nets.latent_layers` (shared with PlaNet); this name stays for old imports."""
from wmdist.nets.latent_layers import _DENSE_ROWS, GRUCell, Heads, Latent, SplitLinear, norm_act, onehot_matmul

__all__ = ["_DENSE_ROWS", "GRUCell", "Heads", "Latent", "SplitLinear", "norm_act", "onehot_matmul"]
