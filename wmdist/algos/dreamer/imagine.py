"""Imagined rollouts from posterior states and the actor-critic losses on them.

`backprop` (V1; V2/V3 continuous) keeps gradients through the learned dynamics to the
actor; the world model's weights are frozen meanwhile so no weight gradients are computed
for them. REINFORCE (V2/V3 discrete) runs the dynamics without autograd at all: only the
actor's forward is recorded.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.nets.kl import masked_mean
from wmdist.nets.latent_layers import Latent
from wmdist.algos.dreamer.nets import ActorCritic, WorldModel
from wmdist.algos.dreamer.replay_value import ReplayStates, replay_lambda_returns
from wmdist.algos.dreamer.returns import PercentileNormalizer, lambda_returns
from wmdist.nets.dists import twohot_mean, twohot_nll


@dataclass
class Start:
    """Posterior states to imagine from (detached), flattened over [B*T] and filtered by mask."""

    deter: torch.Tensor  # [N, D]
    latent: Latent  # [N]
    cont: torch.Tensor  # [N] 1 - terminal of the start state
    rows: torch.Tensor | None = None  # [N] each start's flat row in the replayed batch [B*T]
    replay: ReplayStates | None = None  # the whole batch's states, for the critic replay loss


@dataclass
class Trajectory:
    deter: torch.Tensor  # [H + 1, N, D]
    latent: Latent  # [(H + 1) * N] sampled states only (no gradient path)
    tail_deter: torch.Tensor  # [H * N, D] the imagined states 1..H, with their gradient path under backprop
    tail_latent: Latent  # [H * N] likewise (straight-through probs / reparameterised samples)
    logp: torch.Tensor  # [H, N] log pi(a_t | s_t)
    entropy: torch.Tensor  # [H, N]


def _freeze(module: torch.nn.Module):
    @contextlib.contextmanager
    def ctx():
        flags = [p.requires_grad for p in module.parameters()]
        module.requires_grad_(False)
        try:
            yield
        finally:
            for p, f in zip(module.parameters(), flags):
                p.requires_grad_(f)
    return ctx()


def imagine(
    wm: WorldModel, ac: ActorCritic, start: Start, horizon: int, backprop: bool, generator: torch.Generator | None
) -> Trajectory:
    """Roll the prior forward H steps under the actor from every start state."""
    rssm, spec = wm.rssm, wm.spec
    h, z = start.deter, start.latent
    hs, zs, logps, ents = [h], [z], [], []
    dyn_ctx = contextlib.nullcontext if backprop else torch.no_grad
    for _ in range(horizon):
        dist = ac.policy(h, z)
        a = dist.sample(generator)  # [N] indices or [N, A]
        logps.append(dist.log_prob(a.detach()))
        ents.append(dist.entropy())
        if spec.discrete:
            onehot = F.one_hot(a, spec.num_actions).float()
            a_in = onehot + dist.logp.exp() - dist.logp.exp().detach() if backprop else onehot
        else:
            a_in = a if backprop else a.detach()
        with dyn_ctx():
            h = rssm.img_step(h, z, rssm.action_part(a_in))
            z = rssm.prior_sample(h, generator, grad=backprop)
        hs.append(h)
        zs.append(z)
    # The states 1..H that carry gradients are stacked on their own, and the consumers with a
    # gradient (heads, the returns' critic) read them whole: a slice of an [H + 1] stack would
    # make each backward zero-fill and add [(H + 1) * N, S, C] gradients (~10% of a continuous update).
    n = h.shape[0]
    tail_deter = torch.stack(hs[1:]).flatten(0, 1)  # [H*N, D]
    deter = torch.cat([start.deter, tail_deter.detach()]).reshape(horizon + 1, n, -1)
    if rssm.classes:
        index = torch.stack([z.index for z in zs]).flatten(0, 1)  # [(H+1)*N, S]
        latent = Latent(index=index, classes=rssm.classes)
        probs = torch.stack([z.probs for z in zs[1:]]).flatten(0, 1) if backprop else None  # [H*N, S, C]
        tail = Latent(index=index[n:], probs=probs, classes=rssm.classes)
    else:
        tail_sample = torch.stack([z.sample for z in zs[1:]]).flatten(0, 1)  # [H*N, Z]
        latent = Latent(sample=torch.cat([zs[0].sample, tail_sample]).detach())
        tail = Latent(sample=tail_sample)
    return Trajectory(deter, latent, tail_deter, tail, torch.stack(logps), torch.stack(ents))


def _mark_starts_dynamic(start: Start) -> None:
    """The number of starts follows the batch's real steps, so it changes between updates: compile
    for any N at once (a graph per N would recompile for minutes, and past dynamo's limit run eager)."""
    for x in (start.deter, start.latent.index, start.latent.sample, start.cont, start.rows):
        if x is not None:
            torch._dynamo.maybe_mark_dynamic(x, 0)


class ActorCriticLoss:
    """Computes the actor and critic losses of one update (V1/V2/V3 per config)."""

    def __init__(self, cfg: DreamerConfig, wm: WorldModel, ac: ActorCritic, bins: torch.Tensor) -> None:
        self.cfg, self.wm, self.ac, self.bins = cfg, wm, ac, bins
        self.norm = PercentileNormalizer(cfg.return_decay, cfg.return_low, cfg.return_high)
        discrete = wm.spec.discrete
        self.backprop = (cfg.actor_grad_disc if discrete else cfg.actor_grad_cont) == "backprop"
        self.compiled = False  # set by compile()

    def _value(self, logits: torch.Tensor) -> torch.Tensor:
        if self.cfg.critic_head == "twohot":
            return twohot_mean(logits, self.bins)
        return logits.float().squeeze(-1)

    def __call__(self, start: Start, generator: torch.Generator | None
                 ) -> tuple[torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        """(actor loss, critic loss, metrics as 0-d tensors); `generator` None draws from torch's global RNG."""
        # Under backprop the world model is frozen while the graph is built: the actor's gradient
        # flows through its dynamics but no weight gradients are recorded for it. (Outside `_losses`:
        # requires_grad changes inside a compiled function break its graph.)
        if self.compiled:
            _mark_starts_dynamic(start)
        with _freeze(self.wm) if self.backprop else contextlib.nullcontext():
            return self._losses(start, generator)

    def compile(self) -> None:
        """Runs `_losses` through torch.compile from now on (one graph for the H imagined steps,
        the heads, returns and losses, forward and backward). Pass `generator` None to it: dynamo
        cannot trace draws from a torch.Generator argument and would split the graph at each."""
        self._losses = torch.compile(self._losses)  # type: ignore[method-assign]
        self.compiled = True

    def _losses(self, start: Start, generator: torch.Generator | None
                ) -> tuple[torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        cfg, wm, ac = self.cfg, self.wm, self.ac
        H, n = cfg.horizon, start.deter.shape[0]
        traj = imagine(wm, ac, start, H, self.backprop, generator)
        h_all = traj.deter.flatten(0, 1)  # [(H+1)*N, D] no gradient path
        z_all = traj.latent
        tail_feats = {"h": traj.tail_deter, "z": traj.tail_latent}  # states 1..H, gradient path under backprop
        grad_ctx = contextlib.nullcontext if self.backprop else torch.no_grad
        with grad_ctx():
            # reward and continue of states 1..H (one shared first-layer matmul)
            heads = wm.heads(tail_feats, upto=wm.last_head)
            if cfg.reward_head == "twohot":
                reward = twohot_mean(heads["reward"], self.bins)
            else:
                reward = heads["reward"].float().squeeze(-1)
            reward = reward.reshape(H, n)
            if cfg.cont_head:
                cont = torch.sigmoid(heads["cont"].float().squeeze(-1)).reshape(H, n)
            else:
                cont = torch.ones(H, n, device=reward.device)
        # critic on every imagined state from detached features (trains the critic only)
        feats_sg = {"h": h_all.detach(), "z": z_all.detach()}
        critic_logits = ac.critic(feats_sg)["critic"]  # [(H+1)*N, K]
        value = self._value(critic_logits).reshape(H + 1, n)
        # the values inside the returns: with backprop they must carry the gradient back
        # through the imagined states 1..H, never into the critic's weights (the start
        # states' value is only the first baseline, detached)
        ret_critic = ac.slow_critic if cfg.slow_critic == "target" else ac.critic  # V2: a periodic copy
        if self.backprop:
            with torch.no_grad():
                v0 = value[0] if ret_critic is ac.critic else self._value(ret_critic({"h": start.deter, "z": start.latent})["critic"])
            # the critic with detached weights: no weight gradients for it from the actor's loss
            frozen = {k: w.detach() for k, w in ret_critic.named_parameters()}
            v_tail = self._value(torch.func.functional_call(ret_critic, frozen, (tail_feats,))["critic"])  # [H*N]
            value_ret = torch.cat([v0, v_tail]).reshape(H + 1, n)
        elif ret_critic is ac.slow_critic:
            with torch.no_grad():
                value_ret = self._value(ret_critic(feats_sg)["critic"]).reshape(H + 1, n)
        else:
            value_ret = value.detach()
        disc = cfg.discount * cont  # [H, N]
        returns = lambda_returns(reward, disc, value_ret, cfg.lam)  # [H, N] the critic's targets
        actor_returns = returns  # [H, N] the returns in the actor's advantage
        if cfg.actor_lam is not None and cfg.actor_lam != cfg.lam:
            actor_returns = lambda_returns(reward, disc, value_ret, cfg.actor_lam)
        # weight of step t: start cont times prod_{i<=t} gamma c_i (no credit after a predicted end)
        weight = torch.cat([torch.ones_like(disc[:1]), disc[:-1]]).cumprod(0) * start.cont  # [H, N]
        weight = weight.detach()
        if cfg.return_norm == "percentile":
            self.norm.update(actor_returns)
            scale = self.norm.scale_tensor().to(actor_returns.device)
        else:
            scale = torch.ones((), device=actor_returns.device)
        base = value_ret[:-1].detach()
        adv = (actor_returns - base) / scale  # DreamerV3 eq. 11: normalised advantage
        if self.backprop:
            pg = -adv
        else:
            pg = -traj.logp * adv.detach()  # REINFORCE with the critic as baseline
        actor_loss = masked_mean(pg - cfg.actor_entropy * traj.entropy, weight)
        # critic: regress lambda-returns (+ V3 slow-critic regulariser)
        target = returns.detach()
        logits_h = critic_logits.reshape(H + 1, n, -1)[:-1]
        if cfg.critic_head == "twohot":
            logp_h = F.log_softmax(logits_h.float(), -1)  # [H, N, K], shared by both critic terms
            closs = twohot_nll(logp_h, target, self.bins)
        else:
            closs = 0.5 * (logits_h.float().squeeze(-1) - target).pow(2)
        if cfg.slow_critic == "reg":
            with torch.no_grad():
                slow = self._value(ac.slow_critic({"h": h_all.detach().narrow(0, 0, H * n), "z": _first_rows(z_all.detach(), H * n)})["critic"]).reshape(H, n)
            if cfg.critic_head == "twohot":
                closs = closs + cfg.slow_reg_scale * twohot_nll(logp_h, slow, self.bins)
            else:
                closs = closs + cfg.slow_reg_scale * 0.5 * (logits_h.float().squeeze(-1) - slow).pow(2)
        critic_loss = masked_mean(closs, weight)
        # metrics stay 0-d tensors here: a host sync inside a compiled phase would break its graph
        metrics: dict[str, torch.Tensor] = {}
        if cfg.repval_scale > 0 and start.replay is not None:
            rep_loss, metrics["replay_return"] = self._replay_critic_loss(start, returns[0].detach())
            critic_loss = critic_loss + cfg.repval_scale * rep_loss
            metrics["repval_loss"] = rep_loss.detach()
        metrics.update({
            "actor_loss": actor_loss.detach(),
            "critic_loss": critic_loss.detach(),
            "actor_entropy": traj.entropy.detach().mean(),
            "imag_return": returns.detach().mean(),
            "imag_reward": reward.detach().mean(),
            "value": value.detach().mean(),
            "return_scale": scale.detach(),
        })
        return actor_loss, critic_loss, metrics

    def _replay_critic_loss(self, start: Start, start_returns: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Critic NLL of the replay lambda-returns on every real, non-terminal posterior state.

        start_returns: [N] imagination returns R^lambda_0 of the start states, the value
        annotations where a state was a start (all of them with imag_starts 0); the critic's own
        value elsewhere.
        """
        rep = start.replay
        b, t_len = rep.reward.shape
        logits = self.ac.critic({"h": rep.deter, "z": rep.latent})["critic"]  # [B*T, K]
        annot = self._value(logits).detach().clone()  # [B*T]
        if start.rows is not None:
            annot[start.rows] = start_returns.to(annot.dtype)
        valid = rep.weight > 0
        target = replay_lambda_returns(rep.reward.float(), rep.terminal.bool(), rep.first.bool(), valid,
                                       annot.reshape(b, t_len), self.cfg.discount, self.cfg.lam)  # [B, T]
        if self.cfg.critic_head == "twohot":
            nll = twohot_nll(F.log_softmax(logits.float(), -1), target.flatten(), self.bins)
        else:
            nll = 0.5 * (logits.float().squeeze(-1) - target.flatten()).pow(2)
        w = rep.weight * (1.0 - rep.terminal.float())  # a terminal state has no return to learn
        return masked_mean(nll.reshape(b, t_len), w), masked_mean(target, w).detach()


def _first_rows(lat: Latent, k: int) -> Latent:
    """The first `k` states of a flat latent batch (`narrow`: a slice would fix a symbolic batch size)."""
    cut = lambda x: None if x is None else x.narrow(0, 0, k)  # noqa: E731
    return Latent(cut(lat.index), cut(lat.probs), cut(lat.sample), lat.classes)
