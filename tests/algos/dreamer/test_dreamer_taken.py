"""A recurrent policy told the actions actually taken (the collector's random warm-up)
conditions its next filter step on them, not on the ones it returned."""
from __future__ import annotations

import numpy as np
import torch
from dreamer_loop import tiny_config

from wmdist.algos.dreamer import Dreamer
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec


def test_taken_actions_replace_the_returned_ones():
    spec = env_spec(EnvConfig(id="gym:CartPole-v1"))
    algo = Dreamer(spec, tiny_config(3), 0)
    policy, learner = algo.make_policy(), algo.make_learner()
    policy.set_weights(learner.get_weights(), 0)
    obs = np.zeros((3, 4), np.float32)
    actions, _ = policy.act(obs, np.ones(3, bool), None, None, True)
    other = 1 - np.asarray(actions)
    policy.taken(other)
    want = torch.nn.functional.one_hot(torch.as_tensor(other), 2).float()
    assert torch.equal(policy.prev_action, want)
