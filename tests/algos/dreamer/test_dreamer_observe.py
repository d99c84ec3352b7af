"""RSSM.observe against a plain per-step loop: the optimised loop precomputes the actions'
share of the input layer for the whole sequence and masks only the steps where some row
restarts; values and weight gradients must not change."""
from __future__ import annotations

import pytest
import torch

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.nets import action_to_model
from wmdist.bench.dreamer import bench_spec, random_batch


def _plain_observe(rssm, embed, action, first, generator):
    """The obviously-correct loop: every step masked, each step's action share computed there."""
    b, t_len = first.shape
    keep = (~first).float().unsqueeze(-1)
    keep[:, 0] = 0.0
    h, z = rssm.initial(b)
    a_prev = torch.zeros_like(action[:, 0])
    hs, posts = [], []
    for t in range(t_len):
        h = rssm.img_step(h, z, rssm.action_part(a_prev), keep[:, t])
        post = rssm.post(h, rssm.embed_part(embed[:, t]))
        z = rssm.sample(post, generator)
        a_prev = action[:, t]
        hs.append(h)
        posts.append(post)
    return torch.stack(hs, 1), torch.stack(posts, 1)


@pytest.mark.parametrize("version", [1, 3])  # Gaussian and categorical latents
def test_observe_matches_the_plain_loop_values_and_gradients(version):
    spec = bench_spec(False)
    learner = Dreamer(spec, tiny_config(version), seed=0).make_learner()
    rssm = learner.wm.rssm
    batch = random_batch(spec, 3, 9, seed=1)
    batch["first"][0, 4] = True  # row 0 restarts mid-window; rows 1, 2 do not
    t = learner._tensors(batch)
    embed = learner.wm.encode(t["obs"]).detach()
    action = action_to_model(t["action"], spec)
    first = t["first"].bool()

    def run(fn):
        rssm.zero_grad()
        out = fn(torch.Generator().manual_seed(5))
        (out[0].pow(2).mean() + out[1].pow(2).mean()).backward()
        return [x.detach() for x in out], {k: p.grad.clone() for k, p in rssm.named_parameters() if p.grad is not None}

    (deter, post), grads = run(lambda g: (lambda o: (o.deter, o.post))(rssm.observe(embed, action, first, g)))
    (deter_ref, post_ref), grads_ref = run(lambda g: _plain_observe(rssm, embed, action, first, g))
    torch.testing.assert_close(deter, deter_ref)
    torch.testing.assert_close(post, post_ref)
    assert grads.keys() == grads_ref.keys() and "img_in.weights.a" in grads
    for k in grads:
        torch.testing.assert_close(grads[k], grads_ref[k], msg=k)
    # the restart really restarts: row 0 at step 4 is the zero-state step, like every row at 0
    torch.testing.assert_close(deter[0, 4], deter[1, 0])
    assert not torch.allclose(deter[1, 4], deter[1, 0])


@pytest.mark.parametrize("version", [1, 3])
def test_a_packed_window_carries_nothing_across_an_episode_start(version):
    """replay.pack_episodes puts the end of one episode and the start of the next in one
    window: the second episode's states must not depend on the first one's observations or
    actions (no gradient flows back across `first`), and its first state is the fresh start."""
    spec = bench_spec(False)
    learner = Dreamer(spec, tiny_config(version), seed=0).make_learner()
    rssm = learner.wm.rssm
    batch = random_batch(spec, 2, 9, seed=2)
    batch["first"][:, 4] = True  # both rows: episode A at t=0..3, episode B from t=4
    t = learner._tensors(batch)
    embed = learner.wm.encode(t["obs"]).detach().requires_grad_(True)
    action = action_to_model(t["action"], spec).detach().requires_grad_(True)
    out = rssm.observe(embed, action, t["first"].bool(), torch.Generator().manual_seed(0))
    (out.deter[:, 4:].sum() + out.post[:, 4:].sum()).backward()
    assert embed.grad[:, :4].abs().max() == 0 and action.grad[:, :4].abs().max() == 0
    assert embed.grad[:, 4:].abs().max() > 0  # the check could fail: B's own inputs do reach it
    fresh = rssm.observe(embed[:, 4:].detach(), action[:, 4:].detach(), t["first"][:, 4:].bool(),
                         torch.Generator().manual_seed(0))
    torch.testing.assert_close(out.deter[:, 4], fresh.deter[:, 0])
    torch.testing.assert_close(out.post[:, 4], fresh.post[:, 0])
