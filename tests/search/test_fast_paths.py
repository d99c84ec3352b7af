"""The engine's shortcuts give the same results as the plain paths they replace: reused
workspaces, float32 / strided model outputs read in place, the in-kernel visit policy and
action draw, the flat tree buffers."""
from __future__ import annotations

import threading

import numpy as np
import pytest
import torch

from wmdist.search.api import SearchConfig, SearchOutput, search
from wmdist.search.engine import sample_actions, visit_policy
from wmdist.search.layout import H_SIZE
from wmdist.search.noise import considered_visit_table, draw_root_noise
from wmdist.search.testing import HashModel
from wmdist.search.tree import allocate, layout_of, unpack

torch.set_num_threads(1)


def _search(model: HashModel, batch: int, seed: int, fn=None, **kw) -> SearchOutput:
    latent, logits, value = model.root(batch, seed)
    legal = np.ones((batch, model.num_actions), dtype=bool)
    legal[0, 0] = False
    config = kw.pop("config", SearchConfig(num_simulations=25))
    return search(latent, logits, value, legal, None, fn or model, config, np.random.default_rng(seed), **kw)


def _same(a: SearchOutput, b: SearchOutput) -> None:
    for name in ("visit_counts", "policy", "action", "root_value", "q_values"):
        assert getattr(a, name).tolist() == getattr(b, name).tolist(), name


def test_buffer_regions_are_disjoint_views_of_the_buffer() -> None:
    table = considered_visit_table(4, 7)
    mem = allocate(3, 8, 5, table, 2)
    lay = layout_of(mem)
    assert mem.size == lay.size and mem.ctypes.data % 64 == 0
    assert (lay.node0 * 8) % 64 == 0  # node blocks start on a cache line
    views = unpack(mem)
    assert views["table"].tolist() == table.tolist()
    assert views["nodes"].shape == (3, 8, lay.block) and views["io"].shape == (2, 3, 2)
    mem[...] = 0
    for k, v in enumerate(views.values()):
        v[...] = k + 1  # a later region overlapping an earlier one would overwrite it
    for k, v in enumerate(views.values()):
        assert (v == k + 1).all()
    used = sum(v.size for v in views.values())
    assert np.count_nonzero(mem) == used  # the views write into the buffer
    assert mem.size - used < H_SIZE + 8  # only the header and the alignment gap are not a region


def test_reused_workspaces_give_the_results_of_fresh_ones() -> None:
    """Interleaved shapes, latent kinds and a search aborted half-way leave no trace."""
    model, other = HashModel(5), HashModel(5, torch_latents=True)
    first = _search(model, 3, seed=1)
    _search(other, 3, seed=2)  # same shape, torch latents: a different workspace
    _search(HashModel(7), 2, seed=3)
    calls = [0]

    def fails_half_way(latents, actions):
        calls[0] += 1
        out = model(latents, actions)
        return (np.full(3, np.nan), *out[1:]) if calls[0] == 10 else out

    with pytest.raises(ValueError, match="non-finite"):
        _search(model, 3, seed=4, fn=fails_half_way)
    _same(_search(model, 3, seed=1), first)
    result: list[SearchOutput] = []
    thread = threading.Thread(target=lambda: result.append(_search(model, 3, seed=1)))  # a fresh workspace
    thread.start()
    thread.join()
    _same(result[0], first)


def test_a_search_inside_recurrent_fn_does_not_disturb_the_outer_one() -> None:
    model = HashModel(4)
    plain = _search(model, 2, seed=5)
    inner: list[SearchOutput] = []

    def nested(latents, actions):
        if not inner:
            inner.append(_search(model, 2, seed=6))  # same shape: the outer workspace is busy
        return model(latents, actions)

    _same(_search(model, 2, seed=5, fn=nested), plain)
    _same(inner[0], _search(model, 2, seed=6))


def test_float32_and_strided_model_outputs_are_read_as_their_float64_values() -> None:
    """The kernel reads the model's arrays in place; a float32 output must act exactly like
    its float64 conversion (the old path copied into float64 first)."""
    model = HashModel(6)

    def as_float64(latents, actions):
        r, v, logits, nxt = model(latents, actions)
        return (r.astype(np.float32).astype(np.float64), v.astype(np.float32).astype(np.float64),
                logits.astype(np.float32).astype(np.float64), nxt)

    def as_strided_float32(latents, actions):
        r, v, logits, nxt = model(latents, actions)
        packed = np.concatenate([r[:, None], v[:, None], logits], axis=1).astype(np.float32)  # [B, 2 + A]
        return packed[:, 0], packed[:, 1], packed[:, 2:], nxt  # non-contiguous views

    _same(_search(model, 3, seed=7, fn=as_strided_float32), _search(model, 3, seed=7, fn=as_float64))


@pytest.mark.parametrize("temperature", [0.0, 0.25, 1.0, 3.0])
def test_in_kernel_policy_and_action_match_the_numpy_reference(temperature: float) -> None:
    model = HashModel(9)
    batch = 16
    latent, logits, value = model.root(batch, seed=8)
    legal = np.random.default_rng(8).random((batch, 9)) < 0.8
    legal[:, 4] = True
    config = SearchConfig(num_simulations=40)
    out = search(latent, logits, value, legal, None, model, config, np.random.default_rng(9), temperature=temperature)
    rng = np.random.default_rng(9)
    draw_root_noise(rng, batch, 9, config.dirichlet_alpha, False, True)  # same draws as the search, in order
    policy = visit_policy(out.visit_counts, legal, temperature)
    np.testing.assert_allclose(out.policy, policy, rtol=1e-6, atol=1e-7)
    expected = policy.argmax(axis=1) if temperature == 0 else sample_actions(policy, rng)
    assert out.action.tolist() == expected.tolist()
    assert legal[np.arange(batch), out.action].all()


@pytest.mark.parametrize("torch_latents", [False, True])
def test_tuple_latents_staged_fast_or_by_the_general_path_agree(torch_latents: bool) -> None:
    """A flat tuple of leaves (EfficientZero's (latent, h, c)) is staged leaf by leaf; a
    leaf unlike the root's (here float64 steps, int32 ids) takes the general path, same result."""
    config = SearchConfig(num_simulations=25, value_prefix=True, lstm_horizon=2)
    model = HashModel(4, value_prefix=True, torch_latents=torch_latents)
    fast = _search(model, 3, 7, config=config)

    def odd_dtypes(latents, actions, reset):
        r, v, logits, (ids, since) = model(latents, actions, reset)
        if torch_latents:
            return r, v, logits, (ids, since.double())  # float64: not the root's dtype
        return r, v, logits, (ids.astype(np.int64), since.astype(np.float64))  # float64: not the root's dtype

    _same(fast, _search(model, 3, 7, fn=odd_dtypes, config=config))
