"""What MuZero's self-play policy and its reanalyzer share: a network in eval mode on its
device, a batched searcher over it, and weights loaded from the learner's numpy copy."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Weights
from wmdist.algos.muzero.build import load_numpy_weights
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.algos.muzero.rules_model import rules_for
from wmdist.algos.muzero.searcher import Searcher
from wmdist.envs.spec import EnvSpec


class SearchingRole:
    """Mixin for a role that runs MuZero's search with the latest published weights."""

    def _init_search(self, net: MuZeroNet, cfg: MuZeroConfig, spec: EnvSpec, seed: int, device: str) -> None:
        self.cfg, self.spec = cfg, spec
        self.device = torch.device(device)
        self.net = net.to(self.device).eval()
        self.two_player = spec.players == 2
        self.searcher = Searcher(self.net, cfg.search, cfg.value_support, cfg.reward_support,
                                 self.two_player, self.device,
                                 rules=rules_for(spec) if cfg.tree_model == "rules" else None)
        self.rng = np.random.default_rng(seed)
        self.version = -1

    def set_weights(self, weights: Weights, version: int) -> None:
        load_numpy_weights(self.net, weights)
        self.net.eval()
        self.version = version
