"""PlaNet's learner: the RSSM world model only (there is no policy to train).

Loss per batch (PlaNet eq. 3, plus eq. 7 when overshooting is on):
    recon + reward + kl_scale * max(free, KL(q(s_t | h_t, o_t) || p(s_t | h_t)))  [+ beta * L_os]
with unit-Gaussian observation and reward likelihoods (squared errors) and both sides of the
one-step KL trained.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch

from wmdist.algos.base import Batch, Learner, NonFiniteLoss, UpdateResult, Weights
from wmdist.algos.dreamer.precision import PhasePrecision
from wmdist.algos.planet.config import PlaNetConfig
from wmdist.algos.planet.overshooting import overshooting_kl
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_model
from wmdist.nets.generator import seeded_generator
from wmdist.nets.kl import masked_mean
from wmdist.nets.optim import GuardedStep, OptimConfig
from wmdist.nets.world_model import WorldModel, world_model_weights

FIELDS = ("obs", "action", "reward", "first", "mask")


class PlaNetLearner(Learner):
    def __init__(self, cfg: PlaNetConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        torch.manual_seed(seed)
        self.wm = WorldModel(cfg.world_model(), spec).to(self.device)
        self.opt = GuardedStep(self.wm.parameters(), OptimConfig(kind="adam", lr=cfg.model_lr, eps=cfg.adam_eps,
                                                                 clip_norm=cfg.model_clip))
        self.generator = seeded_generator(self.device, seed)
        self.updates = 0
        # PlaNet's update is Dreamer's world-model phase alone
        self.precision = PhasePrecision({"world_model": cfg.precision}, self.device, cfg.precision_trials)

    def loss(self, batch: Batch) -> tuple[torch.Tensor, dict[str, float]]:
        """The world-model loss of one batch and its parts (floats) for logging."""
        missing = [k for k in FIELDS if k not in batch]
        if missing:
            raise ValueError(f"PlaNet batch lacks fields {missing}")
        t = {k: torch.as_tensor(np.array(batch[k]), device=self.device) for k in FIELDS}  # copy: replay arrays may be read-only
        cfg, wm = self.cfg, self.wm
        b, t_len = t["mask"].shape
        is_weight = torch.as_tensor(np.array(batch["is_weight"]), device=self.device).float() if "is_weight" in batch \
            else torch.ones(b, device=self.device)
        weight = t["mask"].float() * is_weight[:, None]  # [B, T]
        action = action_to_model(t["action"], self.spec)  # [B, T, A]
        first = t["first"].bool()
        obs_out = wm.rssm.observe(wm.encode(t["obs"]), action, first, self.generator)
        h, z = obs_out.deter.flatten(0, 1), obs_out.latent  # [B*T, D], [B*T]
        heads = wm.heads({"h": h, "z": z})
        pred = wm.decode(h, z, heads).float()
        recon = (pred - wm.obs_target(t["obs"]).flatten(0, 1)).pow(2).flatten(1).sum(-1).reshape(b, t_len)  # -log N(o; pred, 1) + c
        rew_l = 0.5 * (heads["reward"].float().squeeze(-1).reshape(b, t_len) - t["reward"].float()).pow(2)
        kl = masked_mean(wm.rssm.kl(obs_out.post, obs_out.prior), weight)  # batch mean, then free nats (PlaNet)
        loss = (cfg.recon_scale * masked_mean(recon, weight) + cfg.reward_scale * masked_mean(rew_l, weight)
                + cfg.kl_scale * torch.clamp(kl, min=cfg.free_nats))
        metrics = {"recon_loss": float(masked_mean(recon.detach(), weight)),
                   "reward_loss": float(masked_mean(rew_l.detach(), weight)), "kl": float(kl.detach())}
        if cfg.overshooting_distance >= 2:
            os_loss, os_kl = overshooting_kl(wm.rssm, obs_out.deter, z, obs_out.post, action, first, weight,
                                             cfg.overshooting_distance, cfg.free_nats, self.generator)
            loss = loss + cfg.overshooting_scale * os_loss
            metrics["overshooting_kl"] = float(os_kl)
        metrics["model_loss"] = float(loss.detach())
        return loss, metrics

    # --- Learner API ----------------------------------------------------------------
    def update(self, batch: Batch) -> UpdateResult:
        prec, spent = self.precision, {}  # spent: seconds of the phase while auto is measuring
        with prec.timed("world_model", spent), prec.autocast("world_model"):
            loss, metrics = self.loss(batch)
        if not torch.isfinite(loss.detach()).all():
            raise NonFiniteLoss(f"planet model loss is {float(loss.detach())}")
        with prec.timed("world_model", spent):
            metrics["model_grad_norm"] = self.opt(loss)
        metrics.update(prec.end_update(spent))
        self.updates += 1
        return UpdateResult(metrics=metrics)

    def get_weights(self) -> Weights:
        return world_model_weights(self.wm)

    def state_dict(self) -> dict[str, Any]:
        return {"wm": self.wm.state_dict(), "opt": self.opt.state_dict(), "generator": self.generator.get_state(),
                "updates": self.updates, "precision": self.precision.state_dict()}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.wm.load_state_dict(state["wm"])
        self.opt.load_state_dict(state["opt"])
        self.generator.set_state(torch.as_tensor(state["generator"]))
        self.updates = int(state["updates"])
        self.precision.load_state_dict(state.get("precision", {}))  # older checkpoints: measure again
