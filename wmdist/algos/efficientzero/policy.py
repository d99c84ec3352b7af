"""EfficientZeroPolicy: MuZero's batched-search policy (the searcher handles the value
prefix); with the off-policy correction it also stores empty reanalyzed value targets."""
from __future__ import annotations

import numpy as np

from wmdist.algos.muzero.policy import MuZeroPolicy


class EfficientZeroPolicy(MuZeroPolicy):
    def act(self, obs, first, legal, to_play, explore):
        actions, extras = super().act(obs, first, legal, to_play, explore)
        if self.cfg.off_policy_correction:  # filled in by the reanalyzers (see reanalyzer.py)
            e = obs.shape[0]
            extras["value_target"] = np.zeros(e, np.float32)
            extras["value_target_set"] = np.zeros(e, bool)
        return actions, extras
