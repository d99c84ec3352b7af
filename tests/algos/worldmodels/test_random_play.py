"""Random play before the controller exists: with `random_keep` each env repeats its last random
action with that probability (runs of 1/(1-p) steps), never across an episode's start."""
import numpy as np

from tests.algos.worldmodels.test_learner import SMALL, SPEC
from wmdist.algos.worldmodels import WorldModels, WorldModelsConfig
from wmdist.envs.spec import EnvSpec

SMALL_Z = WorldModelsConfig().z_dim  # SMALL keeps the default latent size


def _repeats(keep: float, spec: EnvSpec, steps: int = 3000, e: int = 4, first_every: int = 0) -> tuple[float, float]:
    """(share of steps that repeat the env's previous action, the same share at episode starts)."""
    policy = WorldModels(spec, WorldModelsConfig(**{**SMALL, "random_keep": keep})).make_policy("cpu")
    obs = np.zeros((e, *spec.obs_shape), np.uint8)
    prev, same, same_first, n_first = None, 0, 0, 0
    for t in range(steps):
        first = np.full(e, t == 0 or bool(first_every and t % first_every == 0))
        a, _ = policy.act(obs, first, None, None, True)
        if prev is not None:
            eq = np.all(np.asarray(a).reshape(e, -1) == np.asarray(prev).reshape(e, -1), 1)  # [E]
            same += int(eq.sum())
            if first[0]:
                same_first, n_first = same_first + int(eq.sum()), n_first + e
        prev = a
    return same / ((steps - 1) * e), same_first / max(n_first, 1)


def test_random_keep_sets_the_run_length_of_random_actions():
    plain, _ = _repeats(0.0, SPEC)
    assert abs(plain - 1 / 3) < 0.03  # a fresh uniform action of 3 each step
    sticky, at_starts = _repeats(0.9, SPEC, first_every=50)
    assert abs(sticky - (0.9 + 0.1 / 3)) < 0.03
    assert abs(at_starts - 1 / 3) < 0.12  # a new episode draws afresh (60 starts x 4 envs)


def test_random_keep_holds_continuous_actions_too():
    spec = EnvSpec(id="test", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image", action_shape=(3,),
                   action_low=-1.0, action_high=1.0)
    assert _repeats(0.0, spec, steps=500)[0] == 0.0
    assert abs(_repeats(0.8, spec, steps=1500)[0] - 0.8) < 0.04


def test_collect_random_plays_whole_episodes_at_random_beside_the_controller():
    """Once C exists, `collect_random` is the share of collectors' episodes played at random; an
    episode keeps its choice, the evaluator (explore off) always plays C."""
    from wmdist.algos.worldmodels.dream_check import fixed_controllers

    algo = WorldModels(SPEC, WorldModelsConfig(**{**SMALL, "collect_random": 0.5}))
    policy = algo.make_policy("cpu")
    weights = algo.make_learner().get_weights()
    weights["controller"] = fixed_controllers(SPEC, SMALL_Z, SMALL["rnn_hidden"])["always action 2"]
    weights["has_controller"] = np.array(1.0, np.float32)
    policy.set_weights(weights, 1)
    e, length, episodes = 40, 10, 6
    obs = np.zeros((e, *SPEC.obs_shape), np.uint8)
    random_share = []
    for ep in range(episodes):
        acts = np.stack([policy.act(obs, np.full(e, t == 0), None, None, True)[0] for t in range(length)])  # [T, E]
        off_c = (acts != 2).any(0)  # [E] an env that left C's action played this episode at random
        random_share.append(off_c.mean())
        assert ((acts[:, ~off_c] == 2).all())  # the others played C throughout
    assert 0.3 < np.mean(random_share) < 0.65  # ~0.5 x (1 - (1/3)^10)
    greedy = np.stack([policy.act(obs, np.full(e, t == 0), None, None, False)[0] for t in range(length)])
    assert (greedy == 2).all()
