"""JEPA's learner (LeWorldModel's objective, docs/reference.md):

    L = MSE(pred(z_{t-h+1..t}, a_{t-h+1..t}), z_{t+1}) + lambda * SIGReg(z)

(with `rollout_steps` K > 1 the MSE is over the predictor's own K-step rollout from the window's
first history instead, as planning rolls it out)

with z = projector(encoder(frame)) for every real step of the batch (or SIGReg(head(z)) with
`sigreg_head`, LeJEPA's arrangement: the head is regularised, z is what planning compares). Both sides of the MSE
carry gradients: there is no stop-gradient and no EMA target; with `proj_out_norm: false` (the preset) SIGReg
alone keeps the embeddings from collapsing (with `sigreg_weight: 0` they shrink toward a point and the MSE goes to
zero); a last BatchNorm (`proj_out_norm: true`, LeWM's) holds their per-dimension scale by itself.
"""
from __future__ import annotations

import copy
from collections import deque
from typing import Any, Mapping

import numpy as np
import torch

from wmdist.algos.base import Batch, Learner, NonFiniteLoss, UpdateResult, Weights
from wmdist.algos.jepa.config import JepaConfig
from wmdist.algos.jepa.model import FRAME_CHANNELS, GRAPH_KEY, JepaModel, model_weights, recalibrate_batchnorm
from wmdist.algos.jepa.planning import rollout
from wmdist.algos.jepa.sigreg import effective_rank, random_directions, sigreg
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_model
from wmdist.nets.generator import seeded_generator
from wmdist.nets.optim import GuardedStep, OptimConfig
from wmdist.nets.polyak import polyak_

FIELDS = ("obs", "action", "mask")


def history_windows(x: torch.Tensor, h: int) -> torch.Tensor:
    """[B, T, F] -> [B, T - h, h, F]: for each t = h-1 .. T-2 (steps with a next step in the
    window) the h rows ending at t, oldest first."""
    return x.unfold(1, h, 1)[:, : x.shape[1] - h].movedim(-1, 2)


def hold_latest(held: deque[torch.Tensor], rows: torch.Tensor, keep: int) -> None:
    """Append a chunk of rows to `held`; drop whole older chunks the latest `keep` rows no longer need."""
    held.append(rows)
    total = sum(x.shape[0] for x in held)
    while total - held[0].shape[0] >= keep:
        total -= held.popleft().shape[0]


def latest(held: deque[torch.Tensor], keep: int) -> torch.Tensor | None:
    """The latest `keep` rows of `held`'s chunks (None while it is empty)."""
    return torch.cat(list(held))[-keep:] if held else None


class JepaLearner(Learner):
    def __init__(self, cfg: JepaConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        torch.manual_seed(seed)
        self.model = JepaModel(cfg, spec.action_dim).to(self.device)
        self.opt = GuardedStep(self.model.parameters(), OptimConfig(kind="adam", lr=cfg.lr, clip_norm=cfg.grad_clip))
        # What get_weights publishes when cfg.publish_ema > 0: a slow average of the weights, so that the
        # embedding the planner compares distances in changes less from one published version to the next.
        self.ema_model = copy.deepcopy(self.model).eval() if cfg.publish_ema > 0 else None
        self.generator = seeded_generator(self.device, seed)
        self.updates = 0
        self._frames: deque[torch.Tensor] = deque()  # the latest batches' real frames, [N_i, 64, 64, 3] uint8 each
        self._pairs: deque[torch.Tensor] = deque()  # their transitions, [P_i, 2, 64, 64, 3] uint8 each (graph_pairs)

    def loss(self, batch: Batch) -> tuple[torch.Tensor, dict[str, float]]:
        """The JEPA loss of one batch and its parts (floats) for logging."""
        missing = [k for k in FIELDS if k not in batch]
        if missing:
            raise ValueError(f"JEPA batch lacks fields {missing}")
        cfg, h = self.cfg, self.cfg.history
        obs = torch.as_tensor(np.array(batch["obs"]), device=self.device)  # [B, T, 64, 64, 6]
        mask = torch.as_tensor(np.array(batch["mask"]), device=self.device).float()  # [B, T]
        b, t_len = mask.shape
        if t_len <= h:
            raise ValueError(f"JEPA needs sequences longer than algo.history ({h}), got {t_len} steps")
        is_weight = torch.as_tensor(np.array(batch["is_weight"]), device=self.device).float() if "is_weight" in batch \
            else torch.ones(b, device=self.device)
        action = action_to_model(torch.as_tensor(np.array(batch["action"]), device=self.device), self.spec)  # [B, T, A]
        z = self.model.encode(obs[..., :FRAME_CHANNELS])  # [B, T, D]
        z_hist, a_hist = history_windows(z, h), history_windows(action, h)  # [B, T-h, h, D], [B, T-h, h, A]
        target = z[:, h:]  # z_{t+1} [B, T-h, D], with gradients (no stop-gradient)
        w = mask[:, h:] * is_weight[:, None]  # [B, T-h]: the target step is real
        if cfg.rollout_steps > 1:
            pred_loss = self.rollout_loss(z, action, mask[:, h:], is_weight)
        else:
            pred = self.model.predict(z_hist.flatten(0, 1), a_hist.flatten(0, 1)).reshape(b, t_len - h, -1)  # [B, T-h, D]
            mse = ((pred - target) ** 2).mean(-1)  # [B, T-h]
            pred_loss = (mse * w).sum() / w.sum().clamp(min=1.0)
        real = z[mask > 0]  # [N, D] every real step's embedding
        tested = self.model.regularised(real)  # [N, D'] the embeddings, or the SIGReg head's output
        dirs = random_directions(tested.shape[-1], cfg.sigreg_projections, self.generator, self.device)  # [D', M]
        reg = sigreg(tested, dirs, cfg.sigreg_knots, cfg.sigreg_t_max)
        loss = pred_loss + cfg.sigreg_weight * reg
        with torch.no_grad():
            copy = ((z_hist[:, :, -1] - target) ** 2).mean(-1)  # [B, T-h] predicting no change: the bar to beat
            metrics = {"loss": float(loss), "pred_loss": float(pred_loss), "sigreg": float(reg),
                       "copy_loss": float((copy * w).sum() / w.sum().clamp(min=1.0)),
                       "effective_rank": effective_rank(real), "embed_std": float(real.std(0).mean())}
        return loss, metrics

    def rollout_loss(self,
                     z: torch.Tensor,  # [B, T, D] every step's embedding
                     action: torch.Tensor,  # [B, T, A]
                     real: torch.Tensor,  # [B, T-h] 1 where the step after each history is real
                     is_weight: torch.Tensor,  # [B]
                     ) -> torch.Tensor:
        """MSE of K-step open-loop predictions from each window's first history (planning's own
        rollout, `planning.rollout`) against the real z_{h..h+K-1}, averaged over real steps."""
        h, k = self.cfg.history, self.cfg.rollout_steps
        pred = rollout(self.model, z[:, :h], action[:, :h - 1], action[:, h - 1:h - 1 + k])  # [B, K, D]
        w = real[:, :k] * is_weight[:, None]  # [B, K]: past an episode's end nothing is compared
        mse = ((pred - z[:, h:h + k]) ** 2).mean(-1)  # [B, K]
        return (mse * w).sum() / w.sum().clamp(min=1.0)

    def _keep_frames(self, batch: Batch) -> None:
        """Hold the batch's real frames; drop whole older batches the latest `bn_frames` no longer need."""
        real = np.asarray(batch["mask"]) > 0  # [B, T]
        frames = torch.as_tensor(np.asarray(batch["obs"])[..., :FRAME_CHANNELS][real], device=self.device)
        hold_latest(self._frames, frames, self.cfg.bn_frames)

    def _keep_pairs(self, batch: Batch) -> None:
        """Hold the batch's transitions (frames t and t + 1, both real); the latest `graph_pairs` of them."""
        mask = np.asarray(batch["mask"]) > 0  # [B, T]
        b, t = np.nonzero(mask[:, :-1] & mask[:, 1:])  # [P] each: step t and its successor are real
        frames = np.asarray(batch["obs"])[..., :FRAME_CHANNELS]  # [B, T, 64, 64, 3]
        pairs = torch.as_tensor(np.stack([frames[b, t], frames[b, t + 1]], 1), device=self.device)  # [P, 2, ...]
        hold_latest(self._pairs, pairs, self.cfg.graph_pairs)

    @torch.no_grad()
    def graph_nodes(self, model: JepaModel) -> np.ndarray | None:
        """The held transitions' embeddings under `model` (eval mode, as planning embeds): [2P, D], rows
        2i -> 2i+1 one real step (None without graph_pairs or before any update)."""
        pairs = latest(self._pairs, self.cfg.graph_pairs)  # [P, 2, 64, 64, 3]
        if pairs is None:
            return None
        was_training = model.training
        model.eval()
        try:
            z = torch.cat([model.encode(chunk) for chunk in pairs.flatten(0, 1).split(1024)])  # [2P, D]
        finally:
            model.train(was_training)
        return z.float().cpu().numpy()

    @property
    def recent(self) -> torch.Tensor | None:
        """The latest `bn_frames` real frames [<= bn_frames, 64, 64, 3] (None before any update or with bn_frames 0)."""
        return latest(self._frames, self.cfg.bn_frames)

    # --- Learner API ----------------------------------------------------------------
    def update(self, batch: Batch) -> UpdateResult:
        loss, metrics = self.loss(batch)
        if not torch.isfinite(loss.detach()).all():
            raise NonFiniteLoss(f"jepa loss is {float(loss.detach())}")
        metrics["grad_norm"] = self.opt(loss)
        if self.ema_model is not None:  # buffers are re-estimated at publish, not averaged
            polyak_(self.ema_model, self.model, 1.0 - self.cfg.publish_ema, copy_buffers=False)
        if self.cfg.bn_frames:
            self._keep_frames(batch)
        if self.cfg.graph_pairs:
            self._keep_pairs(batch)
        self.updates += 1
        return UpdateResult(metrics=metrics)

    def get_weights(self) -> Weights:
        published = self.ema_model if self.ema_model is not None else self.model
        recent = self.recent
        if recent is not None:  # the statistics planning uses, for exactly these weights
            recalibrate_batchnorm(published, recent)
        out = model_weights(published, self.updates)
        nodes = self.graph_nodes(published)
        if nodes is not None:
            out[GRAPH_KEY] = nodes
        return out

    def state_dict(self) -> dict[str, Any]:
        return {"model": self.model.state_dict(), "opt": self.opt.state_dict(), "generator": self.generator.get_state(),
                "updates": self.updates,
                **({"ema_model": self.ema_model.state_dict()} if self.ema_model is not None else {})}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.model.load_state_dict(state["model"])
        self.opt.load_state_dict(state["opt"])
        self.generator.set_state(torch.as_tensor(state["generator"]))
        self.updates = int(state["updates"])
        if self.ema_model is not None:  # a checkpoint from a run without the average starts it at the weights
            self.ema_model.load_state_dict(state.get("ema_model", state["model"]))
