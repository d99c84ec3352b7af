"""`algo.compile_actor_critic`: the imagination + actor-critic phase through torch.compile gives the
eager learner's losses and weights (the eager learner is the reference), and a machine without a
C++ compiler is refused in one config line."""
import numpy as np
import pytest
import torch
import torch._inductor.config

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.config import cxx_compiler
from wmdist.bench.dreamer import bench_spec, random_batch

LOSSES = ("model_loss", "actor_loss", "critic_loss")


@pytest.mark.skipif(cxx_compiler() is None, reason="inductor needs a C++ compiler on CPU")
@pytest.mark.parametrize("discrete", [True, False], ids=["reinforce", "backprop"])
def test_compiled_actor_critic_matches_eager(discrete):
    # inductor draws through aten's RNG, as eager does: both learners then see the same imagined samples
    with torch._inductor.config.patch(fallback_random=True):
        _compare_compiled_with_eager(discrete)


def _compare_compiled_with_eager(discrete: bool) -> None:
    torch._dynamo.reset()
    spec = bench_spec(discrete)
    cfg = dict(deter=16, units=16, stoch=4, classes=4, horizon=3)
    eager = Dreamer(spec, tiny_config(3, **cfg)).make_learner()
    compiled = Dreamer(spec, tiny_config(3, compile_actor_critic=True, **cfg)).make_learner()
    compiled.load_state_dict(eager.state_dict())  # same weights, optimiser and world-model sampling state
    eager._ac_generator = None  # the reference: the same loss code, eager, drawing from the global RNG
    torch._dynamo.utils.counters.clear()
    for i in range(3):
        batch = random_batch(spec, 4, 8, seed=i)
        torch.manual_seed(100 + i)
        me = eager.update(batch).metrics
        torch.manual_seed(100 + i)
        mc = compiled.update(batch).metrics
        for k in LOSSES + ("actor_entropy", "imag_return", "value", "return_scale"):
            np.testing.assert_allclose(mc[k], me[k], rtol=1e-4, atol=1e-5, err_msg=f"{k} after update {i}")
    assert torch._dynamo.utils.counters["stats"]["unique_graphs"] == 1  # the whole phase in one graph
    for name, p in eager.ac.state_dict().items():  # both trained the same actor and critic
        np.testing.assert_allclose(compiled.ac.state_dict()[name].numpy(), p.numpy(), rtol=1e-3, atol=1e-5, err_msg=name)
    for name, p in eager.wm.state_dict().items():  # and the same world model (no gradient into it from the phase)
        np.testing.assert_allclose(compiled.wm.state_dict()[name].numpy(), p.numpy(), rtol=1e-3, atol=1e-5, err_msg=name)


def test_compile_without_a_cxx_compiler_is_one_config_error(monkeypatch):
    monkeypatch.setenv("CXX", "no-such-compiler-wmdist")
    with pytest.raises(ValueError, match="compile_actor_critic needs a C\\+\\+ compiler"):
        tiny_config(3, compile_actor_critic=True).resolved()
    tiny_config(3).resolved()  # off: no compiler needed
