"""Latent overshooting's batched KL against a plain loop over (batch row, start, distance)."""
import torch

from wmdist.algos.planet.overshooting import overshooting_kl
from wmdist.nets.latent_layers import Latent
from wmdist.nets.rssm import RSSM, RSSMSettings

B, T, E, A = 3, 7, 6, 2


def _setup(seed: int = 0):
    torch.manual_seed(seed)
    rssm = RSSM(RSSMSettings(deter=8, stoch=4, classes=0, units=16, act="elu"), E, A)
    g = torch.Generator().manual_seed(seed)
    embed = torch.randn(B, T, E, generator=g)
    action = torch.rand(B, T, A, generator=g) * 2 - 1
    first = torch.zeros(B, T, dtype=torch.bool)
    first[1, 3] = True  # an episode starts mid-window in row 1
    weight = torch.ones(B, T)
    weight[2, 5:] = 0.0  # padding after the episode's end in row 2
    out = rssm.observe(embed, action, first, g)
    return rssm, out, action, first, weight


@torch.no_grad()
def _reference(rssm, out, action, first, weight, distance, free, seed):
    """Per (b, s, d): roll the prior d steps from the posterior at s; the noise is drawn in the
    same order and shapes as the batched version (one [B, T - d, Z] draw per intermediate step)."""
    g = torch.Generator().manual_seed(seed)
    last = min(distance, T - 1)
    eps = {d: torch.randn(B, T - d, rssm.stoch, generator=g) for d in range(1, last)}
    z_post = out.latent.sample.reshape(B, T, -1)
    sums = {d: 0.0 for d in range(2, last + 1)}
    counts = {d: 0.0 for d in range(2, last + 1)}
    for b in range(B):
        for s in range(T - 1):
            h, z = out.deter[b:b + 1, s], z_post[b:b + 1, s]
            for d in range(1, last + 1):
                if s + d >= T:
                    break
                h = rssm.img_step(h, Latent(sample=z), rssm.action_part(action[b:b + 1, s + d - 1]))
                prior = rssm.prior(h)
                t = s + d
                if d >= 2 and not first[b, s + 1:t + 1].any() and weight[b, t] > 0:
                    sums[d] += float(rssm.kl(out.post[b:b + 1, t], prior)) * float(weight[b, t])
                    counts[d] += float(weight[b, t])
                mean, std = prior.chunk(2, -1)
                z = mean + std * eps[d][b:b + 1, s] if d < last else None
    per_d = [max(free, sums[d] / max(counts[d], 1.0)) for d in sorted(sums)]
    return sum(per_d) / len(per_d), sum(sums.values()) / max(sum(counts.values()), 1.0)


def test_overshooting_matches_the_plain_loop():
    rssm, out, action, first, weight = _setup()
    for distance, free in ((2, 0.0), (4, 0.0), (10, 0.0), (4, 3.0)):
        with torch.no_grad():
            loss, mean_kl = overshooting_kl(rssm, out.deter, out.latent, out.post, action, first, weight, distance,
                                            free, torch.Generator().manual_seed(5))
        ref_loss, ref_kl = _reference(rssm, out, action, first, weight, distance, free, 5)
        assert abs(float(loss) - ref_loss) < 1e-4 * max(1.0, ref_loss), (distance, float(loss), ref_loss)
        assert abs(float(mean_kl) - ref_kl) < 1e-4 * max(1.0, ref_kl)
    assert float(loss) == 3.0  # free nats 3 clip every distance's mean here (an untrained model's KL is small)


def test_overshooting_trains_the_prior_not_the_posterior_target():
    rssm, out, action, first, weight = _setup()
    post = out.post.detach().requires_grad_(True)
    loss, _ = overshooting_kl(rssm, out.deter, out.latent, post, action, first, weight, 4, 0.0)
    loss.backward()
    assert post.grad is None or post.grad.abs().sum() == 0  # the target is stop-gradient
    assert rssm.prior_net[0].weight.grad.abs().sum() > 0  # the multi-step priors are trained
