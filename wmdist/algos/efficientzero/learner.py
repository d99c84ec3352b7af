"""EfficientZeroLearner: MuZero's learner with the value-prefix unroll, the consistency loss
and reanalyzed value targets (written back with the corrected horizon) where replay has them."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Batch
from wmdist.algos.efficientzero.config import EfficientZeroConfig
from wmdist.algos.efficientzero.losses import consistency_loss, prefix_step
from wmdist.algos.efficientzero.networks import EfficientZeroNet
from wmdist.algos.efficientzero.targets import consistency_mask, value_prefix_targets
from wmdist.algos.muzero.learner import MuZeroLearner
from wmdist.algos.muzero.losses import LossOut, LossTargets, unroll_loss
from wmdist.algos.muzero.targets import UnrollTargets


class EfficientZeroLearner(MuZeroLearner):
    cfg: EfficientZeroConfig
    net: EfficientZeroNet

    def _value_targets(self, batch: Batch, tg: UnrollTargets) -> np.ndarray:
        z = super()._value_targets(batch, tg)  # n-step targets: data no reanalyzer has corrected yet
        if not self.cfg.off_policy_correction or "value_target_set" not in batch:
            return z
        t = batch["mask"].shape[1]
        rows = np.arange(len(tg.obs_idx))[:, None]
        pos = np.clip(tg.obs_idx[:, None] + np.arange(z.shape[1])[None, :], 0, t - 1)  # [B, K+1]
        fresh = batch["value_target_set"].astype(bool)[rows, pos] & (tg.policy_w > 0)  # acting steps only
        return np.where(fresh, batch["value_target"].astype(np.float32)[rows, pos], z).astype(np.float32)

    def _reward_targets(self, tg: UnrollTargets) -> np.ndarray:
        if not self.cfg.value_prefix:
            return tg.reward
        return value_prefix_targets(tg.reward, self.cfg.search.lstm_horizon)

    def _losses(self, obs0: torch.Tensor, lt: LossTargets, batch: Batch, tg: UnrollTargets,
                valid: np.ndarray) -> tuple[LossOut, torch.Tensor, dict[str, float]]:
        cfg = self.cfg
        step = prefix_step(self.net, len(obs0), cfg.search.lstm_horizon, self.device) if cfg.value_prefix else None
        out = unroll_loss(self.net, obs0, lt, self.weights, cfg.value_support, cfg.reward_support, step=step)
        if cfg.consistency_weight <= 0:
            return out, out.per_sample, {}
        k = cfg.unroll_steps
        t0 = tg.obs_idx
        idx = np.clip(t0[:, None] + np.arange(1, k + 1)[None, :], 0, batch["mask"].shape[1] - 1)  # [B, K]
        next_obs = self._tensor(batch["obs"][np.arange(len(t0))[:, None], idx])  # [B, K, *obs]
        mask = self._tensor(consistency_mask(batch, t0, valid, k))
        lc = consistency_loss(self.net, out.latents, next_obs, mask)  # [B]
        return out, out.per_sample + cfg.consistency_weight * lc, {"consistency_loss": float(lc.mean().detach())}
