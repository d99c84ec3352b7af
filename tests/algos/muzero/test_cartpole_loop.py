"""A short in-process self-play + learning run on CartPole: the loss falls."""
import numpy as np
import torch

from tests.algos.muzero.loop import InProcessLoop
from wmdist.algos.muzero import MuZero, MuZeroConfig
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec
from wmdist.nets.optim import OptimConfig
from wmdist.search.api import SearchConfig

torch.set_num_threads(1)


def test_cartpole_loss_falls():
    env_cfg = EnvConfig(id="gym:CartPole-v1")
    cfg = MuZeroConfig(
        search=SearchConfig(num_simulations=8), optim=OptimConfig(kind="adam", lr=3e-3),
        latent_dim=32, hidden=[64], value_support=25, reward_support=5, td_steps=10,
    )
    loop = InProcessLoop(MuZero(env_spec(env_cfg), cfg, seed=0), env_cfg, num_envs=8, seq_len=20, overlap=5)
    loop.collect(40)
    assert len(loop.sequences) > 8 and loop.returns
    first = loop.train(5, 64)
    history = []
    for _ in range(8):
        loop.collect(5)
        history += loop.train(10, 64)
    start = np.mean([m["loss"] for m in first])
    end = np.mean([m["loss"] for m in history[-20:]])
    assert end < 0.75 * start, (start, end)
    assert np.mean([m["reward_loss"] for m in history[-20:]]) < first[0]["reward_loss"]
    assert all(np.isfinite(m["loss"]) for m in history)
