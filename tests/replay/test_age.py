"""Step ages: the transitions stored after each sampled step, from the shard's clock (both
backends), through save/restore and restarts, and through the client's draw pools."""
from __future__ import annotations

import numpy as np
from replay_helpers import T, make_batch

from wmdist.replay.batch import step_ages
from wmdist.replay.draws import DrawPool


def _expected_ages(inserted_steps: list[int]) -> dict[int, list[int]]:
    """Plain loop: sequence id -> age of each of its real steps (steps stored after it)."""
    order = [(sid, t) for sid, n in enumerate(inserted_steps) for t in range(n)]  # storage order
    total = len(order)
    ages: dict[int, list[int]] = {}
    for i, (sid, t) in enumerate(order):
        ages.setdefault(sid, []).append(total - 1 - i)
    return ages


def _check(sample: dict, expected: dict[int, list[int]], shards: int = 1) -> None:
    age = step_ages(sample["newer"], sample["mask"], shards)
    ids = sample["data"]["obs"][:, 0, 0].astype(int)
    for row, sid in enumerate(ids):
        n = len(expected[sid])
        assert age[row, :n].tolist() == [shards * a for a in expected[sid]]


def test_ages_count_the_steps_stored_after_each_step(make_shard):
    sh = make_shard(capacity=64)
    steps = [T, 3, 5, T, 1, 7]
    sh.insert(make_batch(3, steps=np.array(steps[:3])))
    sh.insert(make_batch(3, start=3, steps=np.array(steps[3:])))
    expected = _expected_ages(steps)
    _check(sh.sample(200), expected)
    d = sh.draw(50)
    assert d["newer"].tolist() == [expected[int(s)][-1] for s in d["slots"]]  # slot i holds sequence i
    sh.insert(make_batch(1, start=6, steps=np.array([4])))  # everything gets 4 steps older
    _check(sh.sample(200), _expected_ages(steps + [4]))


def test_ages_survive_eviction_and_restore(make_shard, tmp_path):
    ns = f"wmdist:age{tmp_path.name}:s0"  # redis: the restored shard re-reads the same records
    sh = make_shard(capacity=4, namespace=ns)
    steps = [T, 2, 5, 3, T, 6, 1]
    for i, n in enumerate(steps):
        sh.insert(make_batch(1, start=i, steps=np.array([n])))
    expected = _expected_ages(steps)  # the evicted (older) sequences do not change live ages
    _check(sh.sample(300), expected)
    path = str(tmp_path / "shard.npz")
    sh.save(path)
    again = make_shard(capacity=4, namespace=ns)
    again.restore(path)
    _check(again.sample(300), expected)


def test_step_ages_scale_by_shards_and_pad_with_the_last_step():
    mask = np.array([[1, 1, 1, 0], [1, 1, 1, 1]], bool)
    age = step_ages(np.array([10, 0]), mask, shards=2)
    assert age.tolist() == [[24, 22, 20, 20], [6, 4, 2, 0]]


def test_draw_pool_carries_newer_and_tolerates_its_absence():
    pool = DrawPool()
    pool.add({"slots": np.arange(3), "stamps": np.arange(3), "mass": np.ones(3), "keys": ["a", "b", "c"],
              "size": 3, "total": 3.0, "newer": np.array([7, 8, 9])})
    pool.add({"slots": np.arange(2), "stamps": np.arange(2), "mass": np.ones(2), "keys": ["d", "e"],
              "size": 3, "total": 3.0})
    assert pool.take(4)[4].tolist() == [7, 8, 9, 0]
