"""EfficientZero's reanalyzer: MuZero Reanalyze's fresh searches for a share of the sampled
sequences' policy targets, plus value targets with the off-policy-corrected horizon.

For each acting step t of a sampled sequence, with age a_t (transitions stored since t;
replay reports it as `age [B, T]`):
    l_t = clip(n - floor(a_t / tau), 1, n)
    z_t = sum_{j=1..m} gamma^{j-1} r_{t+j} + gamma^m v(o_{t+m}),   m = min(l_t, E - t)
(MuZero's n-step target, Eq. 4, with n replaced by l_t; no bootstrap at a terminal), where v
is the reanalyzer's current network's value or a fresh noise-free root search's. The
written-back `value_target` / `value_target_set` go through replay's stamps like the
policies, so a write-back to a slot rewritten since is dropped and counted.
"""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Batch
from wmdist.algos.efficientzero.config import EfficientZeroConfig
from wmdist.algos.efficientzero.targets import corrected_horizon
from wmdist.algos.muzero.reanalyzer import MuZeroReanalyzer
from wmdist.algos.muzero.targets import acting_steps, make_targets
from wmdist.nets.support import support_to_scalar

TARGET_FIELDS = ("reward", "mask", "first", "last", "terminal", "action", "search_policy")


class EfficientZeroReanalyzer(MuZeroReanalyzer):
    cfg: EfficientZeroConfig

    def reanalyze(self, batch: Batch) -> dict[str, np.ndarray]:
        for k in ("obs", "mask", "last", "search_policy", "search_value"):
            if k not in batch:
                raise ValueError(f"efficientzero reanalyzer: batch lacks field '{k}'")
        acting = acting_steps(batch["mask"], batch["last"])  # [B, T]
        policy = batch["search_policy"].astype(np.float32).copy()  # [B, T, A] kept where not refreshed
        value = batch["search_value"].astype(np.float32).copy()  # [B, T]
        refresh = self.rng.random(len(acting)) < self.cfg.reanalyze_policy_fraction  # [B]
        r, c = np.nonzero(acting & refresh[:, None])
        policy[r, c], value[r, c] = self.search_at(batch, r, c, add_noise=self.cfg.reanalyze_noise)
        out = {"search_policy": policy, "search_value": value}
        if self.cfg.off_policy_correction:
            out.update(self.corrected_value_targets(batch))
        return out

    def corrected_value_targets(self, batch: Batch) -> dict[str, np.ndarray]:
        """{"value_target" [B, T] float32, "value_target_set" [B, T] bool} for every acting step."""
        if "age" not in batch:
            raise ValueError("efficientzero reanalyzer: the off-policy correction needs replay's `age [B, T]`")
        cfg = self.cfg
        acting = acting_steps(batch["mask"], batch["last"])  # [B, T]
        horizon = corrected_horizon(batch["age"], cfg.td_steps, cfg.off_policy_tau)  # [B, T]
        r, c = np.nonzero(acting)  # one target per acting step: N rows of K = 0 targets
        sub = {k: batch[k][r] for k in TARGET_FIELDS}
        gamma = -cfg.search.discount if self.two_player else cfg.search.discount
        tg = make_targets(sub, c, np.ones(len(r), bool), 0, horizon[r, c][:, None], gamma,
                          self.spec.num_actions, self.rng)
        boot = tg.boot_idx[:, 0]  # [N] step index of the bootstrap, -1 at a terminal
        need = boot >= 0
        boot_values = np.zeros(len(r), np.float32)
        if need.any():
            br, bc = r[need], boot[need]
            boot_values[need] = self.values_at(batch, br, bc)
        target = np.zeros(acting.shape, np.float32)
        target[r, c] = tg.value_partial[:, 0] + tg.boot_disc[:, 0] * boot_values
        return {"value_target": target, "value_target_set": acting.copy()}

    @torch.no_grad()
    def values_at(self, batch: Batch, r: np.ndarray, c: np.ndarray) -> np.ndarray:
        """[N] the current model's value of the stored observations at (r, c)."""
        if self.cfg.off_policy_bootstrap == "search":
            return self.search_at(batch, r, c, add_noise=False)[1]
        out = np.zeros(len(r), np.float32)
        for lo in range(0, len(r), self.max_roots):
            obs = torch.as_tensor(np.ascontiguousarray(batch["obs"][r[lo:lo + self.max_roots], c[lo:lo + self.max_roots]]),
                                  device=self.device)
            _, _, v_logits = self.net.initial_inference(obs)
            out[lo:lo + len(obs)] = support_to_scalar(v_logits.float(), self.cfg.value_support).cpu().numpy()
        return out
