"""World Models' staged learner: V, then M, then CMA-ES on C (one generation per update call).

Stage 1 (`vae_updates` calls): V on the batch's frames (vae.py's loss).
Stage 2 (`rnn_updates` calls): M on V's sampled latents of each sequence: from [z_t, a_t] it
    predicts z_{t+1} (mixture NLL, mdn.py) and whether o_{t+1} is terminal (done head).
Stage 3: one CMA-ES generation per call: the pool (role `wm_eval`, handed over by the runtime as
    a service) scores `popsize` candidates on `rollouts` rollouts each, in the dream or the env.
With `iterations` > 1, stage 3 runs in rounds of `generations`, and between two rounds M is
refitted (stage 2 again, `refit_updates` calls) on replay that by then holds the controller's own
episodes; the search goes on from its mean, and its best scores start afresh (they were M's).
The published weights carry V, M and the controller (`controller`, `has_controller`): the best
candidate so far, or with `reeval_every` the best re-evaluated one (pick.py), which the
collectors then act with.
"""
from __future__ import annotations

import time
from typing import Any, Mapping

import numpy as np
import torch

from wmdist.algos.base import Batch, Learner, NonFiniteLoss, UpdateResult, Weights
from wmdist.algos.worldmodels.cmaes import CMAES
from wmdist.algos.worldmodels.config import WorldModelsConfig
from wmdist.algos.worldmodels.controller import num_params
from wmdist.algos.worldmodels.latent_cache import LatentCache, encode_windows
from wmdist.algos.worldmodels.mdn import mdn_log_prob
from wmdist.algos.worldmodels.pick import ControllerPick
from wmdist.algos.worldmodels.models import build_rnn, build_vae, to_numpy
from wmdist.algos.worldmodels.pool import EvalPool
from wmdist.algos.worldmodels.vae import ConvVAE, vae_loss, vae_terms
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_model
from wmdist.nets.generator import seeded_generator
from wmdist.nets.optim import GuardedStep, OptimConfig

POOL_ROLE = "wm_eval"
STAGE_VAE, STAGE_RNN, STAGE_CMA, STAGE_DONE = 0, 1, 2, 3


class WorldModelsLearner(Learner):
    def __init__(self, cfg: WorldModelsConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device, self.seed = cfg, spec, torch.device(device), seed
        torch.manual_seed(seed)
        self.vae = build_vae(cfg, spec).to(self.device)
        self.rnn = build_rnn(cfg, spec).to(self.device)
        self.vae_opt = GuardedStep(self.vae.parameters(), OptimConfig(kind="adam", lr=cfg.vae_lr))
        self.rnn_opt = GuardedStep(self.rnn.parameters(), OptimConfig(kind="adam", lr=cfg.rnn_lr, clip_norm=cfg.rnn_clip))
        self.generator = seeded_generator(self.device, seed)
        self.n_params = num_params(spec, cfg.z_dim, cfg.rnn_hidden, cfg.controller_h)
        self.cma = CMAES(self.n_params, cfg.popsize, cfg.sigma0, seed)
        self.pick = ControllerPick(self.n_params)
        self.bank_mu = np.zeros((0, cfg.z_dim), np.float32)  # [K, Z] first frames' encodings (dream starts)
        self.bank_logvar = np.zeros((0, cfg.z_dim), np.float32)
        self.updates = 0
        self.pool: EvalPool | None = None
        self.latents = LatentCache(cfg.latent_cache) if cfg.latent_cache else None

    # -- the evaluation pool -----------------------------------------------------------------
    def use_services(self, services: Mapping[str, list]) -> None:
        handles = list(services.get(POOL_ROLE, []))
        if handles:
            self.pool = EvalPool(handles, self.cfg.pool_max_retries, self._shares())

    def _pool(self) -> EvalPool:
        if self.pool is None:  # eval_actors = 0 (or a learner built outside a run): dream here
            from wmdist.algos.worldmodels.worker import EvalWorker
            from wmdist.runtime.calls import LocalHandle

            self.pool = EvalPool([LocalHandle(EvalWorker(None, self.spec, 0, 0, algo_config=self.cfg))],
                                 self.cfg.pool_max_retries, self._shares())
        return self.pool

    def _shares(self) -> int:
        """Shares per actor and generation: one batched dream each, or a few real shares (episode
        lengths vary, so smaller shares balance the actors)."""
        return 1 if self.cfg.train_in == "dream" else 2

    def _round(self) -> tuple[int, int]:
        """(round, calls into it) of the search stage; a round is `generations` calls of CMA-ES
        followed, except in the last round, by `refit_updates` calls of M."""
        c = self.cfg
        r = self.updates - c.vae_updates - c.rnn_updates
        if c.generations == 0:
            return 0, r
        return r // (c.generations + c.refit_updates), r % (c.generations + c.refit_updates)

    @property
    def stage(self) -> int:
        c = self.cfg
        if self.updates < c.vae_updates:
            return STAGE_VAE
        if self.updates < c.vae_updates + c.rnn_updates:
            return STAGE_RNN
        i, j = self._round()
        if c.generations == 0 or (i < c.iterations and j < c.generations):
            return STAGE_CMA
        return STAGE_RNN if i < c.iterations - 1 else STAGE_DONE

    @property
    def model_id(self) -> int:
        """V and M are fixed within a round of the search: the pool's actors cache them under this id."""
        return self.cfg.vae_updates + self.cfg.rnn_updates + 1 + self._round()[0]

    def _start_refit(self) -> None:
        """M is about to change: the search's scores so far were M's, so the best ones start afresh
        (the published controller stays until the new M scores another)."""
        self.cma.best_f = -np.inf
        self.pick.f = -np.inf

    # -- stage 1: V --------------------------------------------------------------------------
    def _frames(self, batch: Batch) -> torch.Tensor:
        mask = np.asarray(batch["mask"], bool)  # [B, T]
        frames = np.asarray(batch["obs"])[mask]  # [N, 64, 64, C] real steps only (a copy, writable)
        if self.cfg.vae_frames and len(frames) > self.cfg.vae_frames:
            idx = torch.randperm(len(frames), generator=self.generator, device=self.device)[: self.cfg.vae_frames].cpu().numpy()
            frames = frames[np.sort(idx)]
        return torch.as_tensor(frames, device=self.device)

    def vae_step(self, batch: Batch) -> dict[str, float]:
        obs = self._frames(batch)
        mu, logvar = self.vae.encode(obs)
        recon = self.vae.decode(ConvVAE.sample(mu, logvar, self.generator))
        rec, kl = vae_terms(mu, logvar, recon, obs)
        loss = vae_loss(rec, kl, self.cfg.kl_tolerance, self.cfg.z_dim)
        if not torch.isfinite(loss.detach()):
            raise NonFiniteLoss(f"VAE loss is {float(loss.detach())}")
        grad = self.vae_opt(loss)
        return {"loss": float(loss.detach()), "vae_recon": float(rec.detach().mean()), "vae_kl": float(kl.detach().mean()),
                "vae_grad_norm": grad}

    # -- stage 2: M --------------------------------------------------------------------------
    def rnn_step(self, batch: Batch) -> dict[str, float]:
        obs = np.asarray(batch["obs"])  # [B, T, 64, 64, C]
        mask = torch.as_tensor(np.array(batch["mask"]), device=self.device).float()  # [B, T]
        first = torch.as_tensor(np.array(batch["first"]), device=self.device).bool()
        terminal = torch.as_tensor(np.array(batch["terminal"]), device=self.device).float()
        mu, logvar = self._encode_windows(obs)  # [B, T, Z] each
        with torch.no_grad():
            z = ConvVAE.sample(mu, logvar, self.generator)  # [B, T, Z]: a fresh draw per update, as the authors' M
        self._remember_starts(mu, logvar, first)
        action = action_to_model(torch.as_tensor(np.array(batch["action"]), device=self.device), self.spec)  # [B, T, A]
        log_pi, m, log_s, done_logit, _ = self.rnn(z[:, :-1], action[:, :-1])  # predicts step t+1 from t
        # a pair (t, t+1) counts when both are real steps of one episode (windows hold one episode)
        valid = mask[:, 1:] * mask[:, :-1] * (~first[:, 1:]).float()  # [B, T-1]
        denom = valid.sum().clamp(min=1.0)
        nll = -(mdn_log_prob(log_pi, m, log_s, z[:, 1:]).mean(-1) * valid).sum() / denom  # per dim, as the authors' code
        done = torch.nn.functional.binary_cross_entropy_with_logits(done_logit, terminal[:, 1:], reduction="none")
        done_loss = (done * valid).sum() / denom
        loss = nll + self.cfg.done_weight * done_loss
        if not torch.isfinite(loss.detach()):
            raise NonFiniteLoss(f"MDN-RNN loss is {float(loss.detach())}")
        grad = self.rnn_opt(loss)
        out = {"loss": float(loss.detach()), "rnn_nll": float(nll.detach()), "rnn_done_loss": float(done_loss.detach()),
               "rnn_grad_norm": grad}
        # whether the done head tells deaths apart: its mean probability at real deaths and elsewhere
        p_done, dead = torch.sigmoid(done_logit.detach()), terminal[:, 1:] * valid
        if dead.sum() > 0:
            out["rnn_done_p_death"] = float((p_done * dead).sum() / dead.sum())
        out["rnn_done_p_alive"] = float((p_done * (valid - dead)).sum() / (valid - dead).sum().clamp(min=1.0))
        if self.latents is not None:
            out["rnn_cache_hit_rate"] = self.latents.hits / max(self.latents.hits + self.latents.misses, 1)
        return out

    def _encode_windows(self, obs: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """V's mu, logvar [B, T, Z] of uint8 windows [B, T, 64, 64, C]; V is frozen from stage 2 on, so
        windows replayed again come from the cache (latent_cache.py)."""
        if self.latents is not None:
            return self.latents.encode(obs, self.vae.encode, self.device)
        return encode_windows(obs, self.vae.encode, self.device)

    def _remember_starts(self, mu: torch.Tensor, logvar: torch.Tensor, first: torch.Tensor) -> None:
        """Keep the encodings of episodes' first frames (dreams start from them); the first
        steps of the windows stand in until any true first frame was seen."""
        pick = first.clone()
        if not bool(first.any()) and len(self.bank_mu) == 0:
            pick[:, 0] = True
        new_mu, new_lv = mu[pick].cpu().numpy(), logvar[pick].cpu().numpy()
        self.bank_mu = np.concatenate([self.bank_mu, new_mu])[-self.cfg.z_bank:]
        self.bank_logvar = np.concatenate([self.bank_logvar, new_lv])[-self.cfg.z_bank:]

    # -- stage 3: C --------------------------------------------------------------------------
    def model_payload(self) -> dict[str, np.ndarray]:
        """What an evaluation actor needs: M and the dream starts (dream), or V and M (real)."""
        out = {**to_numpy(self.rnn, "rnn"), "bank_mu": self.bank_mu, "bank_logvar": self.bank_logvar}
        if self.cfg.train_in == "real":
            out.update(to_numpy(self.vae, "vae"))
        return out

    def generation(self) -> dict[str, float]:
        if self.cfg.train_in == "dream" and len(self.bank_mu) == 0:
            raise RuntimeError("the dream has no start latents: M never saw a batch (algo.rnn_updates)")
        t0 = time.monotonic()
        rng = np.random.default_rng([self.seed, self.cma.generation])
        seeds = rng.integers(0, 2**31 - 1, size=self.cfg.rollouts)  # [R] common to every candidate
        pool = self._pool()
        candidates = self.cma.ask()  # [N, P]
        fitness = pool.evaluate(candidates, seeds, self.model_id, self.model_payload, self.cfg.train_in)
        self.cma.tell(candidates, fitness)
        out = {"cma_generation": float(self.cma.generation), "cma_best_fitness": self.cma.best_f,
               "cma_gen_best": float(fitness.max()), "cma_gen_mean": float(fitness.mean()),
               "cma_sigma": self.cma.sigma, "pool_retries": float(pool.retries)}
        c = self.cfg
        g, k = self.cma.generation, self._round()[1] + 1  # k: this generation's place in its round
        if c.reeval_every and (k % c.reeval_every == 0 or k == c.generations):
            reseeds = np.random.default_rng([self.seed, g, 1]).integers(0, 2**31 - 1, size=c.reeval_rollouts)  # [R']
            f = self.pick.offer(lambda x: pool.evaluate(x, reseeds, self.model_id, self.model_payload, c.train_in),
                                {"mean": self.cma.mean, "best": candidates[int(np.argmax(fitness))]})
            out.update({"reeval_mean": float(f[0]), "reeval_gen_best": float(f[1])})
        if self.pick.has:  # every generation, not only re-scoring ones: the driver logs only its tick's last update
            out.update({"pick_fitness": self.pick.f, "pick_is_mean": float(self.pick.source == "mean")})
        out["generation_seconds"] = time.monotonic() - t0
        out["headline_fitness"] = self._published_fitness()
        return out

    def _publishes_pick(self) -> bool:
        """The re-evaluated pick is published once one exists; else the best-ever candidate."""
        return bool(self.cfg.reeval_every and self.pick.has)

    def _published_fitness(self) -> float:
        """The published controller's score (its re-score, or the best-ever candidate's): the
        console shows it as `fitness` while the search has no loss (telemetry/progress.py)."""
        scored = self._publishes_pick() and np.isfinite(self.pick.f)  # -inf: M refitted since the pick
        return float(self.pick.f if scored else self.cma.best_f)

    # -- Learner API -------------------------------------------------------------------------
    def update(self, batch: Batch) -> UpdateResult:
        stage = self.stage
        if stage == STAGE_VAE:
            metrics = self.vae_step(batch)
        elif stage == STAGE_RNN:
            if self.updates >= self.cfg.vae_updates + self.cfg.rnn_updates and self._round()[1] == self.cfg.generations:
                self._start_refit()
            metrics = self.rnn_step(batch)
        elif stage == STAGE_CMA:
            metrics = self.generation()
        else:
            metrics = {"cma_best_fitness": self.cma.best_f, "headline_fitness": self._published_fitness()}
        self.updates += 1
        metrics["stage"] = float(stage)
        if self.cfg.iterations > 1:
            metrics["search_round"] = float(self._round()[0])
        return UpdateResult(metrics=metrics)

    def get_weights(self) -> Weights:
        has = self.cma.generation > 0
        x = self.pick.x if self._publishes_pick() else self.cma.best_x  # [P]
        return {**to_numpy(self.vae, "vae"), **to_numpy(self.rnn, "rnn"),
                "controller": x.astype(np.float32), "has_controller": np.array(float(has), np.float32)}

    def state_dict(self) -> dict[str, Any]:
        return {"vae": self.vae.state_dict(), "rnn": self.rnn.state_dict(), "vae_opt": self.vae_opt.state_dict(),
                "rnn_opt": self.rnn_opt.state_dict(), "generator": self.generator.get_state(), "updates": self.updates,
                "cma": self.cma.state(), "pick": self.pick.state(), "bank_mu": self.bank_mu, "bank_logvar": self.bank_logvar}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.vae.load_state_dict(state["vae"])
        self.rnn.load_state_dict(state["rnn"])
        self.vae_opt.load_state_dict(state["vae_opt"])
        self.rnn_opt.load_state_dict(state["rnn_opt"])
        self.generator.set_state(torch.as_tensor(state["generator"]))
        self.updates = int(state["updates"])
        self.cma.load({k: np.asarray(v) for k, v in state["cma"].items()})
        if "pick" in state:  # checkpoints before session 29 have none
            self.pick.load(state["pick"])
        self.bank_mu = np.asarray(state["bank_mu"], np.float32)
        self.bank_logvar = np.asarray(state["bank_logvar"], np.float32)
