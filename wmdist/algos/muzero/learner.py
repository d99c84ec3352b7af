"""MuZeroLearner: one gradient step on a batch of stored sequences."""
from __future__ import annotations

import contextlib
import copy
from typing import Any, Mapping

import numpy as np
import torch

from wmdist.algos.base import Batch, Learner, UpdateResult, Weights
from wmdist.algos.muzero.build import to_numpy_weights
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.losses import LossOut, LossTargets, LossWeights, unroll_loss
from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.algos.muzero.symmetry import Symmetries
from wmdist.algos.muzero.targets import UnrollTargets, make_targets, sample_starts
from wmdist.nets.optim import GuardedStep
from wmdist.nets.polyak import polyak_
from wmdist.nets.support import support_to_scalar

REQUIRED = ("obs", "action", "reward", "first", "last", "terminal", "search_policy", "search_value", "mask", "is_weight")


class MuZeroLearner(Learner):
    def __init__(self, net: MuZeroNet, cfg: MuZeroConfig, num_actions: int, players: int, seed: int,
                 device: str = "cpu", symmetries: tuple = ()) -> None:
        self.cfg = cfg
        self.device = torch.device(device)
        self.net = net.to(self.device)
        self.target_net = copy.deepcopy(self.net).eval()
        # What get_weights publishes when cfg.publish_ema > 0: a slow average that smooths the
        # acting policy over the last ~1 / (1 - decay) updates.
        self.ema_net = copy.deepcopy(self.net).eval() if cfg.publish_ema > 0 else None
        self.num_actions = num_actions
        # Two-player games: each ply flips the point of view (see targets.py).
        self.gamma = -cfg.search.discount if players == 2 else cfg.search.discount
        self.step = GuardedStep(self.net.parameters(), cfg.optim)
        self.rng = np.random.default_rng(seed)
        self.updates = 0
        self.symmetries = Symmetries(symmetries) if cfg.augment_symmetries else None
        self.weights = LossWeights(cfg.value_loss_weight, cfg.reward_loss_weight, cfg.policy_loss_weight,
                                   cfg.dynamics_grad_scale)

    def _tensor(self, x: np.ndarray, dtype: torch.dtype | None = None) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(x), device=self.device, dtype=dtype)

    @torch.no_grad()
    def _bootstrap_values(self, batch: Batch, tg: UnrollTargets) -> np.ndarray:
        """[B, K+1] values at the bootstrap steps: stored search values, or a network's."""
        b_idx = np.clip(tg.boot_idx, 0, batch["mask"].shape[1] - 1)
        rows = np.arange(b_idx.shape[0])[:, None]
        values = batch["search_value"].astype(np.float32)[rows, b_idx]  # [B, K+1]
        need = tg.boot_idx >= 0
        if self.cfg.bootstrap == "search_value":
            need = need & tg.boot_net  # only final observations lack a search value
        if need.any():
            # bootstrap=search_value: final observations of truncated episodes use the current net.
            net = self.target_net if self.cfg.bootstrap == "target" else self.net
            was_training = net.training
            net.eval()
            r, c = np.nonzero(need)
            obs = self._tensor(batch["obs"][r, b_idx[r, c]])
            _, _, v_logits = net.initial_inference(obs)
            net.train(was_training)
            values[r, c] = support_to_scalar(v_logits.float(), self.cfg.value_support).cpu().numpy()
        return values

    # -- the parts a subclass (EfficientZero) replaces ------------------------------------
    def _value_targets(self, batch: Batch, tg: UnrollTargets) -> np.ndarray:
        """[B, K+1] value targets z (n-step returns, Eq. 4)."""
        return tg.value_target(self._bootstrap_values(batch, tg))

    def _reward_targets(self, tg: UnrollTargets) -> np.ndarray:
        """[B, K+1] targets of the reward head (column 0 unused)."""
        return tg.reward

    def _losses(self, obs0: torch.Tensor, lt: LossTargets, batch: Batch, tg: UnrollTargets,
                valid: np.ndarray) -> tuple[LossOut, torch.Tensor, dict[str, float]]:
        """(the unroll's LossOut, per-sample loss [B], extra metrics)."""
        out = unroll_loss(self.net, obs0, lt, self.weights, self.cfg.value_support, self.cfg.reward_support)
        return out, out.per_sample, {}

    def update(self, batch: Batch) -> UpdateResult:
        missing = [k for k in REQUIRED if k not in batch]
        if missing:
            raise ValueError(f"muzero learner: batch lacks field '{missing[0]}'")
        cfg = self.cfg
        self.net.train()
        t0, valid = sample_starts(batch["mask"], batch["last"], self.rng)
        tg = make_targets(batch, t0, valid, cfg.unroll_steps, cfg.td_steps, self.gamma, self.num_actions, self.rng)
        z = self._value_targets(batch, tg)  # [B, K+1]
        rows = np.arange(len(t0))
        obs0, actions, policy = batch["obs"][rows, t0], tg.actions, tg.policy
        if self.symmetries is not None:
            g = self.rng.integers(0, self.symmetries.size, len(t0))  # [B] one random symmetry per sample
            obs0, actions, policy = self.symmetries.apply(g, obs0, actions, policy)
        lt = LossTargets(
            actions=self._tensor(actions), value=self._tensor(z), value_w=self._tensor(tg.value_w),
            reward=self._tensor(self._reward_targets(tg)), reward_w=self._tensor(tg.reward_w),
            policy=self._tensor(policy), policy_w=self._tensor(tg.policy_w),
        )
        obs0 = self._tensor(obs0)
        is_w = self._tensor(batch["is_weight"], torch.float32) * self._tensor(valid, torch.float32)  # [B]
        amp = torch.autocast("cpu", dtype=torch.bfloat16) if cfg.bf16 else contextlib.nullcontext()
        with amp:
            out, per_sample, extra = self._losses(obs0, lt, batch, tg, valid)
        loss = (per_sample.float() * is_w).mean()
        grad_norm = self.step(loss)  # raises NonFiniteLoss before anything changes
        self.updates += 1
        if cfg.bootstrap == "target" and self.updates % cfg.target_update_every == 0:
            self.target_net.load_state_dict(self.net.state_dict())
        self._update_ema()
        err = np.abs(out.value0.cpu().numpy() - z[:, 0])  # [B] |v^0 - z_t|
        metrics = {
            "loss": float(loss.detach()), "value_loss": float(out.value_loss), "reward_loss": float(out.reward_loss),
            "policy_loss": float(out.policy_loss), "grad_norm": grad_norm, "value_error": float(err[valid].mean()) if valid.any() else 0.0,
            "value_target": float(z[valid, 0].mean()) if valid.any() else 0.0, **extra,
        }
        return UpdateResult(metrics, priorities=(err + cfg.priority_eps).astype(np.float32))

    def _update_ema(self) -> None:
        if self.ema_net is not None:
            polyak_(self.ema_net, self.net, 1.0 - self.cfg.publish_ema)

    def get_weights(self) -> Weights:
        shared = self.ema_net is not None and self.cfg.publish_ema_to == "all"
        return to_numpy_weights(self.ema_net if shared else self.net)

    def get_eval_weights(self) -> Weights | None:
        """publish_ema_to=eval: the average, for the evaluator and checkpoints only."""
        if self.ema_net is not None and self.cfg.publish_ema_to == "eval":
            return to_numpy_weights(self.ema_net)
        return None

    def state_dict(self) -> dict[str, Any]:
        return {
            "net": copy.deepcopy(self.net.state_dict()), "target_net": copy.deepcopy(self.target_net.state_dict()),
            "optim": copy.deepcopy(self.step.state_dict()), "updates": self.updates,
            "rng": self.rng.bit_generator.state,
            **({"ema_net": copy.deepcopy(self.ema_net.state_dict())} if self.ema_net is not None else {}),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.target_net.load_state_dict(state["target_net"])
        self.step.load_state_dict(state["optim"])
        self.updates = int(state["updates"])
        self.rng.bit_generator.state = state["rng"]
        if self.ema_net is not None:  # a checkpoint from a run without the average starts it at the weights
            self.ema_net.load_state_dict(state.get("ema_net", state["net"]))
