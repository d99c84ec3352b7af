"""`algo.compile_actor_critic` and `algo.compile_world_model`: each phase through torch.compile gives
the eager learner's losses and weights (the eager learner is the reference), each compiled phase is
one graph, and a machine without a C++ compiler is refused in one config line."""
import io
from pathlib import Path

import numpy as np
import pytest
import torch
import torch._inductor.config

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.config import cxx_compiler
from wmdist.bench.dreamer import bench_spec, random_batch
from wmdist.config.loader import load_config
from wmdist.runtime.train import _compile_note

PRESETS = Path(__file__).parents[3] / "configs"

LOSSES = ("model_loss", "actor_loss", "critic_loss")


@pytest.mark.skipif(cxx_compiler() is None, reason="inductor needs a C++ compiler on CPU")
@pytest.mark.parametrize("discrete,phases", [  # each phase compiled with each kind of action, in three compiles
    (False, ("actor_critic",)), (True, ("world_model", "actor_critic")), (False, ("world_model",)),
], ids=["backprop", "reinforce-both-phases", "backprop-world-model"])
def test_compiled_phases_match_eager(discrete, phases):
    # inductor draws through aten's RNG, as eager does: both learners then see the same samples
    with torch._inductor.config.patch(fallback_random=True):
        _compare_compiled_with_eager(discrete, phases)


def _compare_compiled_with_eager(discrete: bool, phases: tuple[str, ...]) -> None:
    torch._dynamo.reset()
    spec = bench_spec(discrete)
    cfg = dict(deter=16, units=16, stoch=4, classes=4, horizon=3)
    eager = Dreamer(spec, tiny_config(3, **cfg)).make_learner()
    compiled = Dreamer(spec, tiny_config(3, **{f"compile_{p}": True for p in phases}, **cfg)).make_learner()
    compiled.load_state_dict(eager.state_dict())  # same weights, optimiser and start-picking state
    # the reference: the same loss code, eager, drawing from the global RNG where the compiled one does
    eager._ac_generator = None if "actor_critic" in phases else eager.generator
    eager._wm_generator = None if "world_model" in phases else eager.generator
    torch._dynamo.utils.counters.clear()
    for i in range(3):
        batch = random_batch(spec, 4, 8, seed=i)
        batch["first"][1, 4] = True  # an episode start mid-window: the compiled observe masks every step
        batch["mask"][0, 8 - i:] = False  # padding: the number of imagination starts differs in each update
        torch.manual_seed(100 + i)
        me = eager.update(batch).metrics
        torch.manual_seed(100 + i)
        mc = compiled.update(batch).metrics
        for k in LOSSES + ("recon_loss", "kl_dyn", "actor_entropy", "imag_return", "value", "return_scale"):
            np.testing.assert_allclose(mc[k], me[k], rtol=1e-4, atol=1e-5, err_msg=f"{k} after update {i}")
    # each compiled phase in one graph, compiled once for every number of starts
    assert torch._dynamo.utils.counters["stats"]["unique_graphs"] == len(phases)
    for name, p in eager.ac.state_dict().items():  # both trained the same actor and critic
        np.testing.assert_allclose(compiled.ac.state_dict()[name].numpy(), p.numpy(), rtol=1e-3, atol=1e-5, err_msg=name)
    for name, p in eager.wm.state_dict().items():  # and the same world model
        np.testing.assert_allclose(compiled.wm.state_dict()[name].numpy(), p.numpy(), rtol=1e-3, atol=1e-5, err_msg=name)


def test_compile_without_a_cxx_compiler_is_one_config_error(monkeypatch):
    monkeypatch.setenv("CXX", "no-such-compiler-wmdist")
    with pytest.raises(ValueError, match="compile_actor_critic needs a C\\+\\+ compiler"):
        tiny_config(3, compile_actor_critic=True).resolved()
    with pytest.raises(ValueError, match="compile_world_model needs a C\\+\\+ compiler"):
        tiny_config(3, compile_world_model=True).resolved()
    tiny_config(3).resolved()  # off: no compiler needed


def test_a_run_with_compiled_phases_says_why_its_first_updates_wait():
    out = io.StringIO()
    _compile_note(load_config(PRESETS / "dreamerv3_cartpole.yaml", ["algo.compile_world_model=true"]), out)
    assert "compiles its world-model phase" in out.getvalue()
    out = io.StringIO()
    _compile_note(load_config(PRESETS / "dreamerv3_cartpole.yaml", []), out)
    assert out.getvalue() == ""
