"""ReplayConfig cross-field checks and the capacity split (no Ray)."""
from __future__ import annotations

import numpy as np
import pytest

from wmdist.algos.base import FieldSpec
from wmdist.replay.config import ReplayConfig
from wmdist.runtime.replay_client import route, shard_capacity

FIELDS = {"obs": FieldSpec((20,), "float32"), "last": FieldSpec((), "bool")}  # 81 B/step + 1 B mask


def test_capacity_in_steps_and_bytes():
    assert shard_capacity(ReplayConfig(capacity_steps=6400, seq_len=64, shards=2), FIELDS) == 50
    cfg = ReplayConfig(capacity_steps=6400, seq_len=64, shards=2, capacity_bytes=64 * 82 * 40)
    assert shard_capacity(cfg, FIELDS) == 20  # 40 sequences fit the byte cap, split over 2 shards
    with pytest.raises(ValueError, match="less than one sequence per shard"):
        shard_capacity(ReplayConfig(capacity_steps=6400, seq_len=64, capacity_bytes=100), FIELDS)


def test_validate_cross_field():
    with pytest.raises(ValueError, match="replay.overlap"):
        ReplayConfig(seq_len=8, overlap=8).validate()
    with pytest.raises(ValueError, match="capacity_steps"):
        ReplayConfig(seq_len=64, shards=4, capacity_steps=100).validate()
    ReplayConfig().validate()


def test_route_spreads_episodes_and_is_stable():
    ep = np.arange(4000)
    dest = route(3, ep, 4)
    assert np.array_equal(dest, route(3, ep, 4))
    counts = np.bincount(dest, minlength=4)
    assert counts.min() > 850  # ~1000 each
    assert not np.array_equal(dest, route(4, ep, 4))  # the collector id matters too
