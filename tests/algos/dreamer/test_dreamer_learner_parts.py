"""Imagination gradient routing, the policy's per-env state, and bf16 vs fp32 losses."""
import numpy as np
import pytest
import torch

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.imagine import imagine
from wmdist.bench.dreamer import bench_spec, random_batch


def _ac_losses(discrete):
    spec = bench_spec(discrete)
    learner = Dreamer(spec, tiny_config(3, actor_entropy=0.1)).make_learner()
    t = learner._tensors(random_batch(spec, 3, 6))
    _, _, start = learner.world_model_loss(t)
    actor_loss, critic_loss, _ = learner.ac_loss(start, learner.generator)
    return learner, actor_loss, critic_loss


def test_reinforce_actor_loss_reaches_only_the_actor():
    learner, actor_loss, critic_loss = _ac_losses(discrete=True)
    learner.wm.zero_grad(set_to_none=True)
    actor_loss.backward()
    assert all(p.grad is None for p in learner.wm.parameters())
    assert all(p.grad is None for p in learner.ac.critic.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in learner.ac.actor.parameters())
    critic_loss.backward()
    assert all(p.grad is None for p in learner.wm.parameters())
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in learner.ac.critic.parameters())


def test_backprop_actor_gradient_flows_through_dynamics_but_not_into_model_weights():
    learner, actor_loss, _ = _ac_losses(discrete=False)
    # the imagined states carry the graph: the actor's gradient depends on the dynamics
    actor_loss.backward()
    assert all(p.grad is None for p in learner.wm.parameters())  # world model frozen meanwhile
    assert all(p.requires_grad for p in learner.wm.parameters())  # ... and unfrozen afterwards
    grads = [p.grad for p in learner.ac.actor.parameters() if p.grad is not None]
    assert grads and sum(float(g.abs().sum()) for g in grads) > 0


def _value_only_start(spec, cfg):
    """A learner whose reward head predicts 0 and whose critics start away from zero (twohot critics
    start at zero), and the start states of one batch: the actor's only signal is the critic's value."""
    learner = Dreamer(spec, cfg).make_learner()
    with torch.no_grad():
        reward_out = learner.wm.heads.tails["reward"][-1]
        reward_out.weight.zero_()
        reward_out.bias.zero_()
        for net in (learner.ac.critic, learner.ac.slow_critic):
            torch.nn.init.normal_(net.tails["critic"][-1].weight, std=0.5)
    t = learner._tensors(random_batch(spec, 3, 6))
    _, _, start = learner.world_model_loss(t)
    return learner, start


def test_discrete_backprop_actor_sees_one_hot_actions_and_gets_the_dynamics_gradient():
    """actor_grad_disc=backprop: the dynamics read the sampled one-hot action (straight-through), and
    with rewards zeroed and no entropy term the actor's only gradient comes back through the dynamics
    and the critic's values of the imagined states."""
    cfg = tiny_config(3, actor_grad_disc="backprop", actor_entropy=0.0, cont_head=False)
    learner, start = _value_only_start(bench_spec(True), cfg)

    # the same generator state gives the same actions with and without backprop: the forward pass
    # is the REINFORCE one, only the gradient path differs
    g1, g2 = torch.Generator().manual_seed(5), torch.Generator().manual_seed(5)
    with torch.no_grad():
        plain = imagine(learner.wm, learner.ac, start, 4, False, g1)
    st = imagine(learner.wm, learner.ac, start, 4, True, g2)
    torch.testing.assert_close(st.deter.detach(), plain.deter)

    actor_loss, _, _ = learner.ac_loss(start, learner.generator)
    actor_loss.backward()
    assert all(p.grad is None for p in learner.wm.parameters())
    assert all(p.grad is None for p in learner.ac.critic.parameters())
    grad = sum(float(p.grad.abs().sum()) for p in learner.ac.actor.parameters() if p.grad is not None)
    assert grad > 1e-6


@pytest.mark.parametrize("version", [1, 2, 3])
def test_backprop_actor_gets_the_horizon_values_gradient(version):
    """With rewards and continuation constant, the actor's only signal is the value inside the
    returns: each version's return critic (V2: the target copy) must pass gradient to the states."""
    cfg = tiny_config(version, actor_entropy=0.0, cont_head=False, reward_head="mse")
    learner, start = _value_only_start(bench_spec(False), cfg)
    actor_loss, _, _ = learner.ac_loss(start, learner.generator)
    actor_loss.backward()
    grad = sum(float(p.grad.abs().sum()) for p in learner.ac.actor.parameters() if p.grad is not None)
    assert grad > 1e-6
    assert all(p.grad is None for p in learner.ac.critic.parameters())
    assert all(p.grad is None for p in learner.ac.slow_critic.parameters())


def test_policy_resets_state_only_where_first():
    spec = bench_spec(True)
    algo = Dreamer(spec, tiny_config(3))
    pol = algo.make_policy()
    pol.set_weights(algo.make_learner().get_weights(), 1)
    obs = np.random.default_rng(0).normal(size=(3, 4)).astype(np.float32)
    a, extras = pol.act(obs, np.ones(3, bool), None, None, explore=True)
    assert a.shape == (3,) and a.dtype == np.int64 and extras == {}
    h_first = pol.h.clone()
    for _ in range(3):
        pol.act(obs, np.zeros(3, bool), None, None, explore=True)
    pol.act(obs, np.array([True, False, False]), None, None, explore=True)
    torch.testing.assert_close(pol.h[0], h_first[0])  # env 0 restarted from the zero state
    assert not torch.allclose(pol.h[1], h_first[1])
    legal = np.array([[True, False]] * 3)
    for _ in range(5):  # the legal mask is respected
        a, _ = pol.act(obs, np.zeros(3, bool), legal, None, explore=True)
        assert (a == 0).all()


def test_continuous_policy_actions_in_bounds():
    spec = bench_spec(False)
    for version in (1, 3):
        algo = Dreamer(spec, tiny_config(version))
        pol = algo.make_policy()
        obs = np.zeros((2, 5), np.float32)
        for explore in (True, False):
            a, _ = pol.act(obs, np.ones(2, bool), None, None, explore=explore)
            assert a.shape == (2, 1) and a.dtype == np.float32 and np.all(np.abs(a) <= 1)


def test_v1_explores_with_the_actors_sample_plus_noise():
    """V1 (authors' code): exploring action = clip(actor sample + N(0, 0.3)), not the mode + noise."""
    spec = bench_spec(False)
    algo = Dreamer(spec, tiny_config(1, actor_init_std=1.0, expl_noise=0.3))
    pol = algo.make_policy()
    with torch.no_grad():  # actor output 0: pre-tanh mean 0, std 1 + min_std 0.1; mode 0
        last = pol.ac.actor.tails["actor"][-1]
        last.weight.zero_()
        last.bias.zero_()
    obs = np.zeros((4000, 5), np.float32)
    explored, _ = pol.act(obs, np.ones(4000, bool), None, None, explore=True)
    greedy, _ = pol.act(obs, np.ones(4000, bool), None, None, explore=False)
    np.testing.assert_allclose(greedy, 0.0, atol=1e-6)
    rng = np.random.default_rng(0)  # reference: the same distribution drawn with numpy
    ref = np.clip(np.tanh(rng.normal(0.0, 1.0 + 0.1, 200_000)) + rng.normal(0.0, 0.3, 200_000), -1, 1)
    assert abs(explored.std() - ref.std()) < 0.03  # mode + noise alone would give ~0.3
    assert abs(explored.mean()) < 0.05


def _losses(bf16, seed):
    spec = bench_spec(True)
    learner = Dreamer(spec, tiny_config(3, bf16=bf16, horizon=5), seed=0).make_learner()
    learner.generator.manual_seed(seed)
    t = learner._tensors(random_batch(spec, 4, 10, seed=3))
    with learner._autocast():
        model_loss, m, start = learner.world_model_loss(t)
        actor_loss, critic_loss, _ = learner.ac_loss(start, learner.generator)
    return np.array([float(model_loss.detach()), m["recon_loss"], m["reward_loss"], float(critic_loss.detach())])


def test_bf16_losses_within_sampling_noise_of_fp32():
    torch.set_num_threads(1)
    fp32 = np.stack([_losses(False, s) for s in range(4)])  # [seeds, losses]
    bf16 = np.stack([_losses(True, s) for s in range(4)])
    noise = fp32.std(0) + 1e-3 * np.abs(fp32.mean(0))  # spread from latent / imagination sampling alone
    same_seed_gap = np.abs(bf16 - fp32).mean(0)
    assert np.all(same_seed_gap < 3 * noise + 0.02 * np.abs(fp32.mean(0))), (same_seed_gap, noise)


def test_imag_starts_draws_that_many_distinct_real_states():
    spec = bench_spec(False)
    batch = random_batch(spec, 3, 6)
    batch["mask"][2, 3:] = False  # padding is never a start

    def starts(imag_starts):
        learner = Dreamer(spec, tiny_config(3, imag_starts=imag_starts)).make_learner()
        learner.generator.manual_seed(0)  # same posterior samples, so the same observed states
        return learner.world_model_loss(learner._tensors(batch))[2]

    every, some, more = starts(0), starts(7), starts(100)
    assert every.deter.shape[0] == 15  # 18 steps, 3 of them padding
    assert some.deter.shape[0] == 7 and some.cont.shape == (7,)
    # each drawn start is one of the real states, and none is drawn twice
    key = lambda s: torch.cat([s.deter, s.latent.index.float()], -1)  # noqa: E731 (h alone repeats at window starts)
    match = (key(some)[:, None, :] == key(every)[None, :, :]).all(-1)  # [7, 15]
    assert (match.sum(1) == 1).all() and (match.sum(0) <= 1).all()
    assert more.deter.shape[0] == 15  # more starts than real states: all of them


def test_actor_lambda_changes_the_actors_returns_only(monkeypatch):
    """`actor_lam` feeds the actor's advantage a second lambda-return; the critic's targets stay at `lam`."""
    from wmdist.algos.dreamer import imagine as imagine_mod

    spec = bench_spec(True)
    learner = Dreamer(spec, tiny_config(3, actor_entropy=0.0, return_norm="none")).make_learner()
    t = learner._tensors(random_batch(spec, 3, 6))
    _, _, start = learner.world_model_loss(t)
    g0 = learner.generator.get_state()
    calls = []
    real = imagine_mod.lambda_returns
    monkeypatch.setattr(imagine_mod, "lambda_returns",
                        lambda r, c, v, lam: calls.append((lam, r, c, v)) or real(r, c, v, lam))

    def losses(actor_lam):
        learner.cfg.actor_lam = actor_lam
        learner.generator.set_state(g0)  # the same imagined actions each time
        calls.clear()
        actor, critic, _ = learner.ac_loss(start, learner.generator)
        return float(actor), float(critic), [c[0] for c in calls]

    base_actor, base_critic, lams = losses(None)
    assert lams == [0.95]
    assert losses(0.95)[:3] == (base_actor, base_critic, [0.95])  # the same lambda: nothing recomputed
    td_actor, td_critic, lams = losses(0.0)
    assert lams == [0.95, 0.0] and td_critic == base_critic and td_actor != base_actor
    lam, r, c, v = calls[1]
    assert torch.allclose(real(r, c, v, 0.0), r + c * v[1:])  # lambda 0: the one-step TD target


def test_actor_lr_decay_reaches_its_factor_and_survives_a_checkpoint():
    spec = bench_spec(True)
    cfg = tiny_config(3, actor_lr=1e-3, critic_lr=2e-3, actor_lr_decay_updates=4, actor_lr_decay_to=0.25)
    learner = Dreamer(spec, cfg).make_learner()
    batch = random_batch(spec, 3, 6)
    seen = [learner.update(batch).metrics["actor_lr"] for _ in range(3)]
    # linear from 1e-3 to 2.5e-4 over 4 updates: 1e-3, 8.125e-4, 6.25e-4, 4.375e-4, then 2.5e-4 on
    np.testing.assert_allclose(seen, [1e-3, 8.125e-4, 6.25e-4], rtol=1e-9)
    resumed = Dreamer(spec, cfg).make_learner()
    resumed.load_state_dict(learner.state_dict())
    later = [resumed.update(batch).metrics["actor_lr"] for _ in range(3)]
    np.testing.assert_allclose(later, [4.375e-4, 2.5e-4, 2.5e-4], rtol=1e-9)
    assert resumed.actor_opt.optimizer.param_groups[0]["lr"] == pytest.approx(2.5e-4)
    assert resumed.critic_opt.optimizer.param_groups[0]["lr"] == pytest.approx(2e-3)  # the critic keeps its rate
    assert resumed.wm_opt.optimizer.param_groups[0]["lr"] == pytest.approx(cfg.resolved().model_lr)


def test_without_decay_the_actor_keeps_its_rate():
    spec = bench_spec(True)
    learner = Dreamer(spec, tiny_config(3, actor_lr=1e-3)).make_learner()
    batch = random_batch(spec, 3, 6)
    assert [learner.update(batch).metrics["actor_lr"] for _ in range(3)] == [1e-3] * 3


@pytest.mark.parametrize("slow_critic", ["reg", "target"])  # V3's critic or V2's target copy inside the returns
def test_backprop_actor_gradient_matches_the_plain_full_stack_computation(slow_critic):
    """The actor loss reads the imagined states 1..H as their own stack (no slices of an [H + 1]
    stack, whose backward zero-fills and adds (H + 1) x N x S x C gradients). Reference: the plain
    way, one [H + 1] stack with zero straight-through probs for the start states, heads on a slice
    of it and the returns' critic on all of it; same samples, so the same actor gradient."""
    from wmdist.algos.dreamer.imagine import _freeze
    from wmdist.algos.dreamer.returns import lambda_returns
    from wmdist.nets.dists import twohot_mean
    from wmdist.nets.kl import masked_mean
    from wmdist.nets.latent_layers import Latent

    cfg = tiny_config(3, actor_entropy=0.0, return_norm="none", slow_critic=slow_critic)
    learner, start = _value_only_start(bench_spec(False), cfg)
    wm, ac, c = learner.wm, learner.ac, learner.cfg
    ret_critic = ac.slow_critic if slow_critic == "target" else ac.critic
    with torch.no_grad():  # a reward head that is not zero, so rewards and values both carry gradient
        torch.nn.init.normal_(wm.heads.tails["reward"][-1].weight, std=0.5)

    actor_loss, _, _ = learner.ac_loss(start, torch.Generator().manual_seed(7))
    fast = torch.autograd.grad(actor_loss, list(ac.actor.parameters()))

    n, H = start.deter.shape[0], c.horizon
    with _freeze(wm), _freeze(ret_critic):
        tr = imagine(wm, ac, start, H, True, torch.Generator().manual_seed(7))
        probs = torch.cat([torch.zeros_like(tr.tail_latent.probs[:n]), tr.tail_latent.probs])  # [(H+1)*N, S, C]
        full = {"h": torch.cat([start.deter, tr.tail_deter]), "z": Latent(tr.latent.index, probs, classes=c.classes)}
        tail = {"h": full["h"][n:], "z": Latent(tr.latent.index[n:], probs[n:], classes=c.classes)}
        heads = wm.heads(tail, upto=wm.last_head)
        reward = twohot_mean(heads["reward"], learner.bins).reshape(H, n)
        cont = torch.sigmoid(heads["cont"].float().squeeze(-1)).reshape(H, n)
        value = twohot_mean(ret_critic(full)["critic"], learner.bins).reshape(H + 1, n)
    disc = c.discount * cont
    returns = lambda_returns(reward, disc, value, c.lam)
    weight = (torch.cat([torch.ones_like(disc[:1]), disc[:-1]]).cumprod(0) * start.cont).detach()
    plain = torch.autograd.grad(masked_mean(-(returns - value[:-1].detach()), weight), list(ac.actor.parameters()))

    torch.testing.assert_close(actor_loss, masked_mean(-(returns - value[:-1].detach()), weight))
    for a, b in zip(fast, plain):
        torch.testing.assert_close(a, b)
    assert sum(float(g.abs().sum()) for g in fast) > 1e-6


@pytest.mark.parametrize("discrete", [True, False])
def test_greedy_fraction_makes_the_last_envs_act_on_the_actors_mode_while_the_rest_sample(discrete):
    spec = bench_spec(discrete)
    pol = Dreamer(spec, tiny_config(1, actor_init_std=1.0, expl_noise=0.3, greedy_fraction=0.25)).make_policy()
    modes = []  # each call's mode, read off the distribution the policy acts on (its latents are sampled)
    policy_fn = pol.ac.policy

    def spy(h, z):
        dist = policy_fn(h, z)
        modes.append(dist.mode().cpu().numpy())
        return dist

    pol.ac.policy = spy
    obs = np.random.default_rng(0).normal(size=(8, *spec.obs_shape)).astype(np.float32)
    acted = np.stack([pol.act(obs, np.ones(8, bool), None, None, explore=True)[0] for _ in range(30)])
    mode = np.stack(modes).reshape(acted.shape)  # [30, 8, ...]
    same = np.isclose(acted, mode, atol=1e-6).reshape(30, 8, -1).all(-1)  # [30, 8]
    assert same[:, 6:].all()  # envs 6 and 7 (a quarter of 8): always the mode, no sampling and no noise
    assert not same[:, :6].all(0).any()  # every other env leaves the mode at least once
