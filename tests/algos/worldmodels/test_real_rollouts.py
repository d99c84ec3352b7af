"""Real-env scoring: episodes in lockstep (`real_returns`, what the evaluation actors run) against
one episode at a time (`real_return`, the plain reference), and the actor's fitness from them."""
import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels.config import WorldModelsConfig
from wmdist.algos.worldmodels.controller import act_batched, num_params
from wmdist.algos.worldmodels.models import build_rnn, build_vae, to_numpy
from wmdist.algos.worldmodels.rollout import real_returns
from wmdist.algos.worldmodels.worker import EvalWorker
from wmdist.config.schema import RunConfig
from wmdist.envs import EnvConfig, make_env
from wmdist.nets.actions import action_to_env, action_to_model


@torch.no_grad()
def real_return(
    params,  # [P] one candidate
    env,  # a wmdist Env
    vae,
    rnn,
    spec,
    seed: int,
    max_steps: int | None = None,
    patience: int = 0,
) -> tuple[float, int]:
    """The plain reference: (return, steps) of one real episode, one step at a time; z_t = V's mean of
    o_t, h_t from M; with `patience`, it also ends after that many steps without a positive reward."""
    obs = env.reset(seed)
    state = rnn.initial(1)
    total, steps, idle = 0.0, 0, 0
    while True:
        mu, _ = vae.encode(torch.as_tensor(np.array(obs))[None])  # [1, Z] (a copy: env frames may be read-only)
        a = act_batched(params[None], mu[None], state[0][0][None], spec)[0]  # [1] or [1, A]
        env_a = action_to_env(a, spec)[0]
        obs, reward, term, trunc = env.step(env_a)
        total, steps = total + reward, steps + 1
        idle = 0 if reward > 0 else idle + 1
        a_in = action_to_model(torch.as_tensor(np.asarray(env_a))[None], spec)  # [1, A]
        _, _, _, _, state = rnn.step(mu, a_in, state)
        if term or trunc or (max_steps and steps >= max_steps) or (patience and idle >= patience):
            return total, steps


def _models(spec, z_dim=8, hidden=16):
    torch.manual_seed(0)
    cfg = WorldModelsConfig(z_dim=z_dim, rnn_hidden=hidden, vae_depth=8)
    return cfg, build_vae(cfg, spec).eval(), build_rnn(cfg, spec).eval()


def test_lockstep_equals_one_by_one_with_episodes_of_different_lengths():
    envs = [make_env(EnvConfig(id="carracing:CarRacing-v3", time_limit=t), seed=i) for i, t in enumerate((25, 15, 20))]
    spec = envs[0].spec
    cfg, vae, rnn = _models(spec)
    g = torch.Generator().manual_seed(1)
    for reads_h in (True, False):
        params = torch.randn(3, num_params(spec, cfg.z_dim, cfg.rnn_hidden, reads_h), generator=g)  # [J, P]
        seeds = np.array([5, 6, 5])
        caps = [None, 12]  # the envs' own limits (episodes of 25, 15, 20 steps), and a cap that cuts every episode
        for cap in caps:
            ours = real_returns(params, envs, vae, rnn, spec, seeds, cap)
            ref = [real_return(params[i], envs[i], vae, rnn, spec, int(seeds[i]), cap)[0] for i in range(3)]
            np.testing.assert_allclose(ours, ref, rtol=1e-4, atol=1e-3)
    one = real_returns(params[:1], envs, vae, rnn, spec, seeds[:1], 12)  # fewer episodes than envs
    np.testing.assert_allclose(one, ref[:1], rtol=1e-4, atol=1e-3)
    for e in envs:
        e.close()


def test_the_actor_scores_each_candidate_on_its_seeds_in_chunks():
    run = RunConfig()
    run.env = EnvConfig(id="carracing:CarRacing-v3", time_limit=10)
    env = make_env(run.env, seed=0)
    spec = env.spec
    cfg, vae, rnn = _models(spec)
    cfg.real_envs = 3  # 4 candidates x 2 seeds = 8 episodes: chunks of 3, 3 and 2
    w = EvalWorker(run, spec, 0, threads=1, algo_config=cfg)
    weights = {**to_numpy(vae, "vae"), **to_numpy(rnn, "rnn")}
    weights.update(bank_mu=np.zeros((1, cfg.z_dim), np.float32), bank_logvar=np.zeros((1, cfg.z_dim), np.float32))
    assert w.load_model(3, weights)
    params = torch.randn(4, num_params(spec, cfg.z_dim, cfg.rnn_hidden), generator=torch.Generator().manual_seed(2))
    seeds = np.array([11, 12])
    got = w.evaluate(3, params.numpy(), seeds, "real")["fitness"]
    want = [np.mean([real_return(p, env, vae, rnn, spec, int(s))[0] for s in seeds]) for p in params]
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-3)
    assert len(w.envs) == 3
    env.close()


def test_patience_ends_an_episode_without_rewards_in_both_paths():
    """A car that only brakes earns no tile after the first frames: with patience 25 its episode ends
    25 steps after its last positive reward; one at full gas keeps finding tiles. The same in lockstep
    and one at a time."""
    envs = [make_env(EnvConfig(id="carracing:CarRacing-v3", time_limit=80), seed=i) for i in range(2)]
    spec = envs[0].spec
    cfg, vae, rnn = _models(spec)
    p = num_params(spec, cfg.z_dim, cfg.rnn_hidden)
    brake = torch.zeros(p)
    brake[-3:] = torch.tensor([0.0, -10.0, 10.0])  # bias: no steering, no gas, full brake
    drive = torch.randn(p, generator=torch.Generator().manual_seed(3)) * 0.01
    drive[-3:] = torch.tensor([0.0, 10.0, -10.0])  # full gas, no brake: new tiles keep coming
    params = torch.stack([brake, drive])
    seeds = np.array([1, 2])
    ret, steps = real_return(brake, envs[0], vae, rnn, spec, 1, None, patience=25)
    assert steps < 45  # ended by patience, far short of the 80-step limit
    _, full = real_return(brake, envs[0], vae, rnn, spec, 1, None)
    assert full == 80
    _, driven = real_return(drive, envs[1], vae, rnn, spec, 2, None, patience=25)
    assert driven > steps
    ours = real_returns(params, envs, vae, rnn, spec, seeds, None, patience=25)
    ref = [real_return(params[i], envs[i], vae, rnn, spec, int(seeds[i]), None, patience=25)[0] for i in range(2)]
    np.testing.assert_allclose(ours, ref, rtol=1e-4, atol=1e-3)
    assert ours[0] == pytest.approx(ret, abs=1e-3)
    for e in envs:
        e.close()
