"""The recurrent state-space model (PlaNet) shared by PlaNet and Dreamer V1/V2/V3.

State s_t = (h_t, z_t). Transition h_t = GRU(h_{t-1}, img_in([z_{t-1}, a_{t-1}])); prior
p(z_t | h_t); posterior q(z_t | h_t, e_t) with e_t the observation embedding. The latent is
Gaussian (V1, `classes = 0`) or `stoch` categoricals of `classes` classes (V2/V3) with an
optional uniform mix (V3). "Stats" are a tensor: categorical log-probs [..., S, C], or the
Gaussian's [mean, std] concatenated [..., 2S].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch
import torch.nn.functional as F
from torch import nn

from wmdist.nets.latent_layers import GRUCell, Latent, SplitLinear, norm_act
from wmdist.nets.dists import categorical_kl, gaussian_kl, randn_as, sample_index_from_probs, unimix_logits


class RSSMConfig(Protocol):
    """The fields the RSSM reads (a resolved `DreamerConfig` or `RSSMSettings`)."""

    deter: int  # GRU width
    stoch: int  # Gaussian size, or number of categoricals
    classes: int  # classes per categorical (0 = Gaussian latent: PlaNet, Dreamer V1)
    units: int  # hidden width of the prior/posterior MLPs and the transition's input layer
    act: str  # activation (a key of `wmdist.nets.mlp.ACTIVATIONS`)
    norm: bool  # LayerNorm in the hidden layers
    gru_norm: bool  # LayerNorm inside the GRU
    unimix: float  # uniform mix in every categorical (0 for Gaussians)


@dataclass(frozen=True)
class RSSMSettings:
    """A concrete `RSSMConfig` for algorithms whose config names these fields differently."""

    deter: int
    stoch: int
    classes: int
    units: int
    act: str
    norm: bool = False
    gru_norm: bool = False
    unimix: float = 0.0


@dataclass
class Observed:
    """What `RSSM.observe` returns for a [B, T] batch."""

    deter: torch.Tensor  # [B, T, D]
    post: torch.Tensor  # [B, T, stats]
    prior: torch.Tensor  # [B, T, stats]
    latent: Latent  # [B*T] posterior samples (straight-through where categorical)


class RSSM(nn.Module):
    def __init__(self, cfg: RSSMConfig, embed_dim: int, action_dim: int) -> None:
        super().__init__()
        self.cfg = cfg
        self.deter, self.stoch, self.classes = cfg.deter, cfg.stoch, cfg.classes
        self.z_dim = cfg.stoch * cfg.classes if cfg.classes else cfg.stoch
        stat_dim = self.z_dim if cfg.classes else 2 * cfg.stoch
        u, act, norm = cfg.units, cfg.act, cfg.norm
        self.img_in = SplitLinear({"z": self.z_dim, "a": action_dim}, u, bias=not norm)
        self.img_in_act = norm_act(u, act, norm)
        self.gru = GRUCell(u, cfg.deter, cfg.gru_norm)
        self.prior_net = nn.Sequential(nn.Linear(cfg.deter, u, bias=not norm), norm_act(u, act, norm), nn.Linear(u, stat_dim))
        self.post_in = SplitLinear({"h": cfg.deter, "e": embed_dim}, u, bias=not norm)
        self.post_out = nn.Sequential(norm_act(u, act, norm), nn.Linear(u, stat_dim))

    # --- distributions -------------------------------------------------------------
    def stats(self, out: torch.Tensor) -> torch.Tensor:
        out = out.float()
        if self.classes:
            return unimix_logits(out.unflatten(-1, (self.stoch, self.classes)), self.cfg.unimix)
        mean, std = out.chunk(2, -1)
        return torch.cat([mean, F.softplus(std) + 0.1], -1)

    def sample(self, stats: torch.Tensor, generator: torch.Generator | None = None, grad: bool = True) -> Latent:
        """Draw z; `grad` keeps the straight-through / reparameterised path to the stats."""
        if self.classes:
            probs = stats.exp()
            index = sample_index_from_probs(probs, generator)
            return Latent(index=index, probs=probs if grad else None, classes=self.classes)
        mean, std = stats.chunk(2, -1)
        eps = randn_as(mean, generator)
        z = mean + std * eps
        return Latent(sample=z if grad else z.detach())

    def mode(self, stats: torch.Tensor) -> Latent:
        if self.classes:
            return Latent(index=stats.argmax(-1), classes=self.classes)
        return Latent(sample=stats.chunk(2, -1)[0])

    def kl(self, p: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """KL(p || q) per state -> [...]."""
        if self.classes:
            return categorical_kl(p, q)
        mp, sp = p.chunk(2, -1)
        mq, sq = q.chunk(2, -1)
        return gaussian_kl(mp, sp, mq, sq)

    # --- steps ---------------------------------------------------------------------
    def initial(self, n: int, device: torch.device | str = "cpu") -> tuple[torch.Tensor, Latent]:
        h = torch.zeros(n, self.deter, device=device)
        if self.classes:
            return h, Latent(index=torch.zeros(n, self.stoch, dtype=torch.long, device=device), classes=self.classes)
        return h, Latent(sample=torch.zeros(n, self.z_dim, device=device))

    def img_step(self, h: torch.Tensor, z: Latent, a_part: torch.Tensor, keep: torch.Tensor | None = None) -> torch.Tensor:
        """h_t from (h_{t-1}, z_{t-1}, a_{t-1}); rows with keep = 0 restart from the zero state.

        `a_part` is a_{t-1}'s share of the input layer, `action_part(a_{t-1})`: observe computes
        it for a whole sequence in one matmul."""
        scale = None
        if keep is not None:
            scale = {"z": keep}
            h = h * keep
            a_part = a_part * keep.to(a_part.dtype)
        x = self.img_in_act(self.img_in({"z": z}, pre=a_part, scale=scale))
        return self.gru(x, h)

    def action_part(self, action: torch.Tensor) -> torch.Tensor:
        """The action's share of the transition's input layer, [..., A] -> [..., U], in one matmul."""
        return self.img_in.part("a", action)

    def prior(self, h: torch.Tensor) -> torch.Tensor:
        return self.stats(self.prior_net(h))

    def prior_sample(self, h: torch.Tensor, generator: torch.Generator | None = None, grad: bool = True) -> Latent:
        """z ~ p(z | h). Without gradients a categorical skips the log: probs are mixed and sampled directly."""
        if grad or not self.classes:
            return self.sample(self.prior(h), generator, grad)
        probs = torch.softmax(self.prior_net(h).float().unflatten(-1, (self.stoch, self.classes)), -1)
        if self.cfg.unimix > 0:
            probs = probs * (1 - self.cfg.unimix) + self.cfg.unimix / self.classes
        return Latent(index=sample_index_from_probs(probs, generator), classes=self.classes)

    def embed_part(self, embed: torch.Tensor) -> torch.Tensor:
        """The embedding's share of the posterior's first layer (for a whole sequence at once)."""
        return self.post_in.part("e", embed)

    def post(self, h: torch.Tensor, e_part: torch.Tensor) -> torch.Tensor:
        return self.stats(self.post_out(self.post_in({"h": h}, pre=e_part)))

    def observe(
        self,
        embed: torch.Tensor,  # [B, T, E]
        action: torch.Tensor,  # [B, T, A] model-space actions; action[t] is taken at o_t
        first: torch.Tensor,  # [B, T] bool
        generator: torch.Generator | None = None,
    ) -> Observed:
        b, t_len = first.shape
        e_part = self.embed_part(embed)  # [B, T, U], one matmul for the whole sequence
        keep = (~first).float().unsqueeze(-1)  # [B, T, 1]
        keep[:, 0] = 0.0  # a sampled window starts from the zero state
        if torch.compiler.is_compiling():
            # a host read would split a compiled graph; masking by keep = 1 multiplies by one exactly
            resets = [True] * t_len
        else:  # steps where no row restarts skip the masking (most of them: ~10% fewer ops per step)
            resets = (keep.squeeze(-1) == 0).any(0).tolist()  # [T]
        # a_{t-1} enters step t: the actions' share for the whole sequence in one matmul
        a_prev = torch.cat([torch.zeros_like(action[:, :1]), action[:, :-1]], 1)  # [B, T, A]
        a_part = self.action_part(a_prev)  # [B, T, U]
        h, z = self.initial(b, embed.device)
        hs, posts, zs = [], [], []
        for t in range(t_len):
            h = self.img_step(h, z, a_part[:, t], keep[:, t] if resets[t] else None)
            post = self.post(h, e_part[:, t])
            z = self.sample(post, generator)
            hs.append(h)
            posts.append(post)
            zs.append(z)
        deter = torch.stack(hs, 1)
        prior = self.prior(deter)  # [B, T, stats]: the prior is not needed inside the loop
        if self.classes:
            latent = Latent(
                index=torch.stack([z.index for z in zs], 1).flatten(0, 1),
                probs=torch.stack([z.probs for z in zs], 1).flatten(0, 1),
                classes=self.classes,
            )
        else:
            latent = Latent(sample=torch.stack([z.sample for z in zs], 1).flatten(0, 1))
        return Observed(deter, torch.stack(posts, 1), prior, latent)
