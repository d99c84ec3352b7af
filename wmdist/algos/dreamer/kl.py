"""The KL loss moved to `wmdist.nets.kl` (shared with PlaNet); this name stays for old imports."""
from wmdist.nets.kl import kl_loss, masked_mean

__all__ = ["kl_loss", "masked_mean"]
