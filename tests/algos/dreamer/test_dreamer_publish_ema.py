"""algo.publish_ema for Dreamer: the published world model and actor are a Polyak average of the
learner's, equal to a plain per-update loop, kept across a checkpoint; the policy loads them."""
import numpy as np

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.bench.dreamer import bench_spec, random_batch


def _own(learner) -> dict[str, np.ndarray]:
    out = {f"wm.{k}": v.detach().numpy().copy() for k, v in learner.wm.state_dict().items()}
    out.update({f"actor.{k}": v.detach().numpy().copy() for k, v in learner.ac.actor.state_dict().items()})
    return out


def test_published_weights_are_the_average_of_a_plain_loop_and_survive_a_checkpoint():
    spec, decay = bench_spec(True), 0.7
    algo = Dreamer(spec, tiny_config(3, publish_ema=decay))
    learner = algo.make_learner()
    batch = random_batch(spec, 3, 6)
    ref = _own(learner)
    buffers = {f"wm.{k}" for k, _ in learner.wm.named_buffers()} | {f"actor.{k}" for k, _ in learner.ac.actor.named_buffers()}
    for _ in range(3):
        learner.update(batch)
        own = _own(learner)
        ref = {k: own[k] if k in buffers else decay * ref[k] + (1 - decay) * own[k] for k in ref}
    pub = learner.get_weights()
    assert set(pub) == set(ref)
    for k in ref:
        np.testing.assert_allclose(pub[k], ref[k], rtol=1e-5, atol=1e-6, err_msg=k)
    own = _own(learner)
    assert max(float(np.abs(pub[k] - own[k]).max()) for k in own) > 1e-5  # it lags the learner
    policy = algo.make_policy("cpu")
    policy.set_weights(pub, 3)  # the names and shapes a collector loads

    resumed = Dreamer(spec, tiny_config(3, publish_ema=decay)).make_learner()
    resumed.load_state_dict(learner.state_dict())
    for k, v in pub.items():
        np.testing.assert_array_equal(resumed.get_weights()[k], v, err_msg=k)


def test_zero_decay_publishes_the_learner_weights():
    spec = bench_spec(False)
    learner = Dreamer(spec, tiny_config(3)).make_learner()
    learner.update(random_batch(spec, 3, 6))
    pub = learner.get_weights()
    for k, v in _own(learner).items():
        np.testing.assert_array_equal(pub[k], v, err_msg=k)
