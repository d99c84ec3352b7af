"""MuZero Reanalyze (paper Appendix H): rerun the search with the latest weights over every
stored step of the sampled sequences and return fresh policy and value targets."""
from __future__ import annotations

import numpy as np

from wmdist.algos.base import Batch, Reanalyzer
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.algos.muzero.searching import SearchingRole
from wmdist.algos.muzero.targets import acting_steps
from wmdist.envs.spec import EnvSpec

# Search calls get batches padded to a multiple of this. The search's workspaces
# ([B, nodes, latent words], wmdist/search/workspace.py) are cached by B, and the number of
# stored steps differs in every sampled batch: unpadded, each call allocated a fresh buffer
# of ~200 MB (1,000 MinAtar roots) and the reanalyzer's memory swung between 4 and 7 GB.
ROOT_BUCKET = 64


class MuZeroReanalyzer(SearchingRole, Reanalyzer):
    def __init__(self, net: MuZeroNet, cfg: MuZeroConfig, spec: EnvSpec, seed: int, device: str = "cpu",
                 max_roots: int = 256) -> None:
        self._init_search(net, cfg, spec, seed, device)
        self.max_roots = max_roots  # roots per search call (bounds the tree's memory)
        self.root_bucket = ROOT_BUCKET  # search batches padded to a multiple of this (1: unpadded)

    def search_at(self, batch: Batch, r: np.ndarray, c: np.ndarray, add_noise: bool) -> tuple[np.ndarray, np.ndarray]:
        """Search the stored observations at rows r, steps c ([N] each) -> (policy targets
        [N, A], root values [N]), in chunks of `max_roots`."""
        a = self.spec.num_actions
        policy, value = np.zeros((len(r), a), np.float32), np.zeros(len(r), np.float32)
        for lo in range(0, len(r), self.max_roots):
            rr, cc = r[lo:lo + self.max_roots], c[lo:lo + self.max_roots]
            n = len(rr)  # the real roots; padding repeats the last one
            rr, cc = pad_roots(rr, cc, self.root_bucket)
            legal = batch["legal"][rr, cc].astype(bool) if "legal" in batch else np.ones((len(rr), a), bool)
            to_play = batch["to_play"][rr, cc].astype(np.int64) if self.two_player and "to_play" in batch else None
            res = self.searcher.run(batch["obs"][rr, cc], legal, to_play, self.rng, add_noise=add_noise)
            policy[lo:lo + n] = res.policy_target[:n]
            value[lo:lo + n] = res.root_value[:n]
        return policy, value

    def reanalyze(self, batch: Batch) -> dict[str, np.ndarray]:
        for k in ("obs", "mask", "last", "search_policy", "search_value"):
            if k not in batch:
                raise ValueError(f"muzero reanalyzer: batch lacks field '{k}'")
        acting = acting_steps(batch["mask"], batch["last"])  # [B, T]
        policy = np.zeros_like(batch["search_policy"], dtype=np.float32)  # [B, T, A]
        value = np.zeros_like(batch["search_value"], dtype=np.float32)  # [B, T]
        r, c = np.nonzero(acting)
        # Root noise as in self-play (reanalyze_noise): the stored targets came from noised
        # searches too, and a noise-free search on a peaked prior can put every visit on one
        # action, so the policy target sharpens the prior further until it collapses.
        policy[r, c], value[r, c] = self.search_at(batch, r, c, add_noise=self.cfg.reanalyze_noise)
        return {"search_policy": policy, "search_value": value}


def pad_roots(r: np.ndarray, c: np.ndarray, bucket: int) -> tuple[np.ndarray, np.ndarray]:
    """(r, c) [N] extended to a multiple of `bucket` by repeating the last root."""
    pad = -len(r) % bucket
    if pad == 0:
        return r, c
    return np.concatenate([r, np.repeat(r[-1:], pad)]), np.concatenate([c, np.repeat(c[-1:], pad)])
