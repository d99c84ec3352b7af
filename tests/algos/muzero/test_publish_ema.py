"""algo.publish_ema: the published weights are a Polyak average of the learner's, equal to a
plain per-update loop, kept across a checkpoint, and the learner's own when the decay is 0."""
import numpy as np
import torch

from tests.algos.efficientzero.common import small_algo
from tests.algos.muzero.helpers import random_batch


def _own(learner) -> dict[str, np.ndarray]:
    return {k: v.detach().numpy().copy() for k, v in learner.net.state_dict().items()}


def test_published_weights_are_the_average_of_a_plain_loop():
    decay = 0.8
    learner = small_algo(publish_ema=decay).make_learner()
    ref = _own(learner)  # the average starts at the initial weights
    buffers = {k for k, _ in learner.net.named_buffers()}
    assert buffers  # the check below covers both kinds of tensor
    rng = np.random.default_rng(0)
    for _ in range(4):
        learner.update(random_batch(rng, 8, 12, 3))
        own = _own(learner)
        # parameters averaged; buffers (the projector's BatchNorm statistics) are the learner's own
        ref = {k: own[k] if k in buffers else decay * ref[k] + (1 - decay) * own[k] for k in ref}
    pub = learner.get_weights()
    assert set(pub) == set(ref)
    for k in ref:
        np.testing.assert_allclose(pub[k], ref[k], rtol=1e-5, atol=1e-6)
    # the average lags: it is not the learner's own weights after 4 updates of decay 0.8
    own = _own(learner)
    assert max(float(np.abs(pub[k] - own[k]).max()) for k in own) > 1e-4


def test_zero_decay_publishes_the_learner_weights_and_the_average_survives_a_checkpoint():
    rng = np.random.default_rng(1)
    plain = small_algo().make_learner()
    plain.update(random_batch(rng, 8, 12, 3))
    for k, v in _own(plain).items():
        np.testing.assert_array_equal(plain.get_weights()[k], v)

    a = small_algo(publish_ema=0.9).make_learner()
    for _ in range(3):
        a.update(random_batch(rng, 8, 12, 3))
    state = a.state_dict()
    b = small_algo(publish_ema=0.9).make_learner()
    b.load_state_dict(state)
    for k, v in a.get_weights().items():
        np.testing.assert_array_equal(b.get_weights()[k], v)
    batch = random_batch(np.random.default_rng(2), 8, 12, 3)
    torch.manual_seed(0); a.update(batch)
    torch.manual_seed(0); b.update(batch)
    for k, v in a.get_weights().items():
        np.testing.assert_allclose(b.get_weights()[k], v, rtol=1e-6, atol=1e-7)
    # a checkpoint written without the average (publish_ema was 0) starts it at the weights
    c = small_algo(publish_ema=0.9).make_learner()
    c.load_state_dict(plain.state_dict())
    for k, v in _own(plain).items():
        np.testing.assert_array_equal(c.get_weights()[k], v)
