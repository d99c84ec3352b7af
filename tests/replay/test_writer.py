"""SequenceWriter: windows, overlap, masks at episode ends, versions, discard, bad input."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.algos.base import FieldSpec
from wmdist.replay.writer import SequenceWriter

FIELDS = {"obs": FieldSpec((2,), "float32"), "action": FieldSpec((), "int64"), "last": FieldSpec((), "bool")}


def _step(t: int, last: list[bool]) -> dict[str, np.ndarray]:
    E = len(last)
    return {"obs": np.full((E, 2), t, np.float32), "action": np.arange(E, dtype=np.int64) + 100 * t,
            "last": np.array(last)}


def test_windows_overlap_and_padding():
    w = SequenceWriter(FIELDS, seq_len=4, overlap=2, num_envs=2)
    # env 0: episode of 7 steps (t=0..6); env 1: one long episode, never ends
    for t in range(7):
        w.add(_step(t, [t == 6, False]), version=10 + t)
        if t == 2:
            assert w.pending() == 0  # nothing is visible before a window is complete
    b = w.pop()
    env0 = b.episode_id == 0
    obs0 = b.data["obs"][env0][..., 0]
    # windows start every T - overlap = 2 steps; the last one is padded after t=6
    assert obs0.tolist() == [[0, 1, 2, 3], [2, 3, 4, 5], [4, 5, 6, 0]]
    assert b.mask[env0].astype(int).tolist() == [[1, 1, 1, 1], [1, 1, 1, 1], [1, 1, 1, 0]]
    assert b.data["action"][env0][2, 3] == 0 and not b.data["last"][env0][2, 3]
    assert b.data["last"][env0][2, 2]
    assert b.version[env0].tolist() == [10, 12, 14]  # oldest version inside each window
    assert b.data["obs"][b.episode_id == 1][..., 0].tolist() == [[0, 1, 2, 3], [2, 3, 4, 5]]
    assert len(w.pop()) == 0


def test_episode_ending_on_window_boundary_and_new_episode_ids():
    w = SequenceWriter(FIELDS, seq_len=3, overlap=1, num_envs=1)
    for t in range(5):  # 5 steps = windows [0,1,2] and [2,3,4]; the end falls on a boundary
        w.add(_step(t, [t == 4]))
    w.add(_step(9, [True]))  # a 1-step episode
    b = w.pop()
    assert b.data["obs"][..., 0].tolist() == [[0, 1, 2], [2, 3, 4], [9, 0, 0]]
    assert b.mask.sum(1).tolist() == [3, 3, 1]
    assert b.episode_id[0] == b.episode_id[1] != b.episode_id[2]


def _packed_reference(streams: list[list[int]], T: int, overlap: int) -> list[list[int]]:
    """Slow reference: each env's steps end to end, cut into windows of T every T - overlap steps."""
    out = []
    for stream in streams:
        start = 0
        while start + T <= len(stream):
            out.append(stream[start:start + T])
            start += T - overlap
    return out


@pytest.mark.parametrize("overlap", [0, 2])
def test_packed_windows_run_across_episode_ends(overlap):
    """pack=True: an episode's end leaves its window open for the env's next episode, so
    every window is T real steps (no padding), `last` stays inside it, and the windows are
    exactly the env's step stream cut every T - overlap steps."""
    rng = np.random.default_rng(0)
    T, E, n = 5, 3, 40
    w = SequenceWriter(FIELDS, seq_len=T, overlap=overlap, num_envs=E, pack=True)
    streams: list[list[int]] = [[] for _ in range(E)]
    for t in range(n):
        last = (rng.random(E) < 0.3).tolist()  # episodes of 1-3 steps are common: most would be padding
        w.add(_step(t, last))
        for e in range(E):
            streams[e].append(t)
    b = w.pop()
    assert b.mask.all()
    got = sorted(b.data["obs"][..., 0].astype(int).tolist())
    assert got == sorted(_packed_reference(streams, T, overlap))
    assert b.data["last"].any(axis=1).sum() > len(b) // 2  # episode ends sit inside windows


def test_packed_window_keeps_its_first_episode_id_and_discard_starts_fresh():
    w = SequenceWriter(FIELDS, seq_len=3, overlap=0, num_envs=1, pack=True)
    w.add(_step(0, [True]))  # a 1-step episode, then a second one in the same window
    w.add(_step(1, [False]))
    w.add(_step(2, [False]))
    w.add(_step(3, [False]))
    w.discard([0])  # the unfinished window [3] is dropped
    for t in (4, 5, 6):
        w.add(_step(t, [False]))
    b = w.pop()
    assert b.data["obs"][..., 0].tolist() == [[0, 1, 2], [4, 5, 6]]
    assert b.episode_id[0] != b.episode_id[1]


def test_discard_drops_unfinished_window():
    w = SequenceWriter(FIELDS, seq_len=4, overlap=0, num_envs=2)
    for t in range(3):
        w.add(_step(t, [False, False]))
    w.discard([0])
    for t in range(3, 5):
        w.add(_step(t, [False, False]))
    b = w.pop()
    assert len(b) == 1 and b.data["obs"][0, :, 0].tolist() == [0, 1, 2, 3] and b.data["action"][0, 0] == 1


@pytest.mark.parametrize("change, msg", [
    (lambda s: s.pop("obs"), "'obs' is missing"),
    (lambda s: s.update(obs=s["obs"].astype(np.float64)), "'obs': dtype float64"),
    (lambda s: s.update(obs=np.zeros((2, 3), np.float32)), r"'obs': shape \(2, 3\)"),
    (lambda s: s.update(action=[1, 2]), "'action': expected a numpy array"),
    (lambda s: s.update(last=np.zeros(3, bool)), "'last': shape"),
])
def test_bad_step_rejected_with_field_name(change, msg):
    w = SequenceWriter(FIELDS, seq_len=4, overlap=0, num_envs=2)
    s = _step(0, [False, False])
    change(s)
    with pytest.raises(ValueError, match=msg):
        w.add(s)


def test_bad_construction():
    with pytest.raises(ValueError, match="overlap"):
        SequenceWriter(FIELDS, seq_len=4, overlap=4, num_envs=1)
    with pytest.raises(ValueError, match="'last'"):
        SequenceWriter({"last": FieldSpec((), "float32")}, 4, 0, 1)
