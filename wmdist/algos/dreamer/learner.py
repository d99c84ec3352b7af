"""Dreamer's learner: world-model update on [B, T] sequences, then actor-critic in imagination."""
from __future__ import annotations

import contextlib
import copy
import dataclasses
from typing import Any, Mapping

import numpy as np
import torch

from wmdist.algos.base import Batch, Learner, NonFiniteLoss, UpdateResult, Weights
from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.algos.dreamer.imagine import ActorCriticLoss, Start
from wmdist.algos.dreamer.nets import ActorCritic, WorldModel, action_to_model
from wmdist.algos.dreamer.precision import PhasePrecision
from wmdist.algos.dreamer.replay_value import ReplayStates
from wmdist.envs.spec import EnvSpec
from wmdist.nets.dists import bernoulli_nll, twohot_bins, twohot_loss
from wmdist.nets.generator import seeded_generator
from wmdist.nets.kl import kl_loss, masked_mean
from wmdist.nets.latent_layers import Latent
from wmdist.nets.optim import GuardedStep, OptimConfig, joint_step, lr_at
from wmdist.nets.polyak import polyak_
from wmdist.nets.world_model import load_world_model, world_model_weights


def policy_weights(wm: WorldModel, actor: torch.nn.Module) -> Weights:
    """World model + actor as numpy (what policies and the dream video need)."""
    out = world_model_weights(wm)
    out.update({f"actor.{k}": v.detach().cpu().numpy() for k, v in actor.state_dict().items()})
    return out


def load_policy_weights(wm: WorldModel, ac: ActorCritic, weights: Weights) -> None:
    actor_sd = {k[6:]: torch.as_tensor(np.array(v)) for k, v in weights.items() if k.startswith("actor.")}
    if not actor_sd:
        raise ValueError("Dreamer weights need 'wm.*' and 'actor.*' entries")
    load_world_model(wm, weights)
    ac.actor.load_state_dict(actor_sd)


class DreamerLearner(Learner):
    def __init__(self, cfg: DreamerConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        torch.manual_seed(seed)
        self.wm = WorldModel(cfg, spec).to(self.device)
        self.ac = ActorCritic(cfg, spec, self.wm.rssm.z_dim).to(self.device)
        self.bins = twohot_bins(cfg.bins, cfg.bin_low, cfg.bin_high).to(self.device)
        self.ac_loss = ActorCriticLoss(cfg, self.wm, self.ac, self.bins)
        if cfg.compile_actor_critic:
            self.ac_loss.compile()

        def opt(lr: float, clip: float, **schedule: Any) -> OptimConfig:
            return OptimConfig(kind="adam", lr=lr, eps=cfg.adam_eps, clip_norm=clip, **schedule)

        actor_schedule = ({"schedule": "linear", "decay_steps": cfg.actor_lr_decay_updates,
                           "decay_rate": cfg.actor_lr_decay_to} if cfg.actor_lr_decay_updates else {})
        self.wm_opt = GuardedStep(self.wm.parameters(), opt(cfg.model_lr, cfg.model_clip))
        self.actor_opt = GuardedStep(self.ac.actor.parameters(), opt(cfg.actor_lr, cfg.ac_clip, **actor_schedule))
        self.critic_opt = GuardedStep(self.ac.critic.parameters(), opt(cfg.critic_lr, cfg.ac_clip))
        self.generator = seeded_generator(self.device, seed)
        # A compiled phase draws from torch's global RNG (seeded above; not in the checkpoint): dynamo
        # cannot trace draws from a torch.Generator argument and would split its graph at each.
        self._ac_generator = None if cfg.compile_actor_critic else self.generator
        self._wm_generator = None if cfg.compile_world_model else self.generator
        if cfg.compile_world_model:
            self._wm_losses = torch.compile(self._wm_losses)  # type: ignore[method-assign]
        self.updates = 0
        follow = "bf16" if cfg.bf16 else "fp32"
        # What get_weights publishes when cfg.publish_ema > 0: slow copies of the world model and actor.
        self.ema: tuple[WorldModel, torch.nn.Module] | None = (
            (copy.deepcopy(self.wm).requires_grad_(False), copy.deepcopy(self.ac.actor).requires_grad_(False))
            if cfg.publish_ema > 0 else None)
        self.precision = PhasePrecision(
            {"world_model": cfg.precision_world_model or follow, "actor_critic": cfg.precision_actor_critic or follow},
            self.device, cfg.precision_trials)

    # --- losses ---------------------------------------------------------------------
    def _autocast(self):
        """The whole update's forward under `bf16` (the precision of both phases before they were split)."""
        if self.cfg.bf16:
            return torch.autocast(self.device.type, dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def _tensors(self, batch: Batch) -> dict[str, torch.Tensor]:
        for key in ("obs", "action", "reward", "first", "terminal", "mask"):
            if key not in batch:
                raise ValueError(f"Dreamer batch lacks field {key!r}")
        out = {k: torch.as_tensor(np.array(v), device=self.device) for k, v in batch.items()}  # copy: replay arrays may be read-only
        b = out["mask"].shape[0]
        out["is_weight"] = out["is_weight"].float() if "is_weight" in out else torch.ones(b, device=self.device)
        return out

    def world_model_loss(self, t: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float], Start]:
        cfg = self.cfg
        loss, metrics_t, h, z = self._wm_losses(t, self._wm_generator)
        metrics = {k: float(v) for k, v in metrics_t.items()}
        rows = torch.nonzero(t["mask"].flatten() > 0).squeeze(-1)  # imagine only from real steps
        if 0 < cfg.imag_starts < rows.numel():
            # a random subset: the actor-critic cost scales with the starts, its gradient is an
            # average over starts x H states, so fewer starts mostly add noise, not bias
            pick = torch.randperm(rows.numel(), generator=self.generator, device=rows.device)[: cfg.imag_starts]
            rows = rows[pick]
        replay = None
        if cfg.repval_scale > 0:
            weight = t["mask"].float() * t["is_weight"][:, None]  # [B, T]
            replay = ReplayStates(h.detach(), z.detach(), t["reward"].float(), t["terminal"].bool(), t["first"].bool(),
                                  weight)
        cont_target = 1.0 - t["terminal"].float()
        start = Start(h.detach()[rows], _select(z.detach(), rows), cont_target.flatten()[rows], rows, replay)
        return loss, metrics, start

    def _wm_losses(self, t: dict[str, torch.Tensor], generator: torch.Generator | None
                   ) -> tuple[torch.Tensor, dict[str, torch.Tensor], torch.Tensor, Latent]:
        """(model loss, metrics as 0-d tensors, posterior states h [B*T, D] and z [B*T]).

        No host reads here (compiled with `algo.compile_world_model`: one graph for the T observe steps,
        heads and losses); `generator` None draws from torch's global RNG."""
        cfg, wm = self.cfg, self.wm
        b, t_len = t["mask"].shape
        weight = t["mask"].float() * t["is_weight"][:, None]  # [B, T]
        embed = wm.encode(t["obs"])  # [B, T, E]
        obs_out = wm.rssm.observe(embed, action_to_model(t["action"], self.spec), t["first"].bool(), generator)
        h = obs_out.deter.flatten(0, 1)  # [B*T, D]
        z = obs_out.latent
        heads = wm.heads({"h": h, "z": z})
        target = wm.obs_target(t["obs"]).flatten(0, 1)
        pred = wm.decode(h, z, heads).float()
        recon = (pred - target).pow(2).flatten(1).sum(-1).reshape(b, t_len)  # Gaussian NLL up to a constant
        reward = t["reward"].float()
        if cfg.reward_head == "twohot":
            rew_l = twohot_loss(heads["reward"], reward.flatten(), self.bins).reshape(b, t_len)
        else:
            rew_l = 0.5 * (heads["reward"].float().squeeze(-1).reshape(b, t_len) - reward).pow(2)
        loss = cfg.recon_scale * masked_mean(recon, weight) + cfg.reward_scale * masked_mean(rew_l, weight)
        metrics: dict[str, torch.Tensor] = {}
        if cfg.cont_head:
            cont_target = 1.0 - t["terminal"].float()
            cont_l = bernoulli_nll(heads["cont"].squeeze(-1).reshape(b, t_len), cont_target)  # [B, T]
            term_w = 1.0 + (cfg.cont_terminal_weight - 1.0) * t["terminal"].float()  # [B, T] extra weight on ends
            loss = loss + cfg.cont_scale * masked_mean(cont_l * term_w, weight)
            metrics["cont_loss"] = masked_mean(cont_l.detach(), weight)
        kl, dyn, rep = kl_loss(wm.rssm.kl, obs_out.post, obs_out.prior, weight, cfg.kl_dyn, cfg.kl_rep, cfg.free_nats, cfg.free_avg)
        loss = loss + kl
        metrics.update(
            model_loss=loss.detach(), recon_loss=masked_mean(recon.detach(), weight),
            reward_loss=masked_mean(rew_l.detach(), weight), kl_dyn=dyn, kl_rep=rep,
        )
        return loss, metrics, h, z

    # --- Learner API ----------------------------------------------------------------
    def update(self, batch: Batch) -> UpdateResult:
        t = self._tensors(batch)
        prec, spent = self.precision, {}  # spent: seconds per phase (while auto is measuring)
        with prec.timed("world_model", spent), prec.autocast("world_model"):
            model_loss, metrics, start = self.world_model_loss(t)
        if prec.mode("actor_critic") == "fp32" and start.deter.dtype != torch.float32:
            # a bf16 world model hands over bf16 states
            replay = start.replay and dataclasses.replace(start.replay, deter=start.replay.deter.float())
            start = dataclasses.replace(start, deter=start.deter.float(), replay=replay)
        with prec.timed("actor_critic", spent), prec.autocast("actor_critic"):
            actor_loss, critic_loss, ac_metrics = self.ac_loss(start, self._ac_generator)
        for name, loss in (("model", model_loss), ("actor", actor_loss), ("critic", critic_loss)):
            if not torch.isfinite(loss.detach()).all():
                raise NonFiniteLoss(f"dreamer {name} loss is {float(loss.detach())}")
        # one backward for both (a compiled phase returns them from one graph), before any weight changes:
        # the actor's graph reads the critic's and world model's current weights
        with prec.timed("actor_critic", spent):
            metrics["actor_lr"] = lr_at(self.actor_opt.cfg, self.actor_opt.steps)  # the rate this step applies
            metrics["actor_grad_norm"], metrics["critic_grad_norm"] = joint_step(
                [(self.actor_opt, actor_loss), (self.critic_opt, critic_loss)])
        with prec.timed("world_model", spent):
            metrics["model_grad_norm"] = self.wm_opt(model_loss)
        metrics.update(prec.end_update(spent))
        self.updates += 1
        if self.cfg.slow_critic != "none" and self.updates % self.cfg.slow_critic_every == 0:
            self.ac.update_slow(self.cfg.slow_critic_mix)
        if self.ema is not None:
            polyak_(self.ema[0], self.wm, 1.0 - self.cfg.publish_ema)
            polyak_(self.ema[1], self.ac.actor, 1.0 - self.cfg.publish_ema)
        metrics.update({k: float(v) for k, v in ac_metrics.items()})
        return UpdateResult(metrics=metrics)

    def get_weights(self) -> Weights:
        return policy_weights(*self.ema) if self.ema is not None else policy_weights(self.wm, self.ac.actor)

    def state_dict(self) -> dict[str, Any]:
        return {
            "wm": self.wm.state_dict(), "ac": self.ac.state_dict(),
            "wm_opt": self.wm_opt.state_dict(), "actor_opt": self.actor_opt.state_dict(),
            "critic_opt": self.critic_opt.state_dict(), "return_norm": self.ac_loss.norm.state_dict(),
            "generator": self.generator.get_state(), "updates": self.updates,
            "precision": self.precision.state_dict(),
            **({"ema_wm": self.ema[0].state_dict(), "ema_actor": self.ema[1].state_dict()} if self.ema else {}),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.wm.load_state_dict(state["wm"])
        self.ac.load_state_dict(state["ac"])
        self.wm_opt.load_state_dict(state["wm_opt"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.ac_loss.norm.load_state_dict(state["return_norm"])
        self.generator.set_state(torch.as_tensor(state["generator"]))
        self.updates = int(state["updates"])
        self.precision.load_state_dict(state.get("precision", {}))  # older checkpoints: measure again
        if self.ema is not None:  # a checkpoint from a run without the average starts it at the weights
            self.ema[0].load_state_dict(state.get("ema_wm", state["wm"]))
            self.ema[1].load_state_dict(state.get("ema_actor", self.ac.actor.state_dict()))


def _select(lat: Latent, rows: torch.Tensor) -> Latent:
    """The states `rows` (indices [K] or a mask [N])."""
    pick = lambda x: None if x is None else x[rows]  # noqa: E731
    return Latent(pick(lat.index), pick(lat.probs), pick(lat.sample), lat.classes)
