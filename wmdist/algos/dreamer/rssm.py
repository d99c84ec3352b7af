"""The RSSM moved to `wmdist.nets.rssm` (shared with PlaNet); this name stays for old imports."""
from wmdist.nets.rssm import RSSM, Observed

__all__ = ["RSSM", "Observed"]
