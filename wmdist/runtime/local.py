"""A run's roles as plain objects in this process, stepped by hand.

`wmdist train --local` lets the driver schedule the roles; `LocalSession` hands them to the
caller instead, for tests and notebooks that want to collect a few segments, look at what
replay holds, take an update and look again. The collector, replay and learner are the
runtime's own (built by `topology.build(local=True)`), so a test sees the records and the
step convention a real run stores.
"""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from wmdist.config.schema import RunConfig


class LocalSession:
    def __init__(self, cfg: RunConfig, run_dir: str | Path | None = None) -> None:
        from wmdist.envs.factory import env_spec
        from wmdist.runtime.roles.setup import build_algorithm
        from wmdist.runtime.topology import build

        self.cfg = cfg
        self.spec = env_spec(cfg.env)
        fields = build_algorithm(cfg, self.spec, cfg.run.seed).step_fields()
        self._tmp = None
        if run_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="wmdist-local-")
            run_dir = self._tmp.name
        self.topo = build(cfg, self.spec, Path(run_dir), fields, local=True)
        self.collectors = [h.local_object for h in self.topo.collectors]
        self.learner_role = self.topo.learner.local_object
        self.env_steps = 0
        self.returns: list[float] = []

    # -- the parts -------------------------------------------------------------------------
    @property
    def learner(self) -> Any:
        """The algorithm's Learner."""
        return self.learner_role.learner

    @property
    def algo(self) -> Any:
        return self.learner_role.algo

    @property
    def policy(self) -> Any:
        """Collector 0's Policy."""
        return self.collectors[0].policy

    @property
    def replay(self) -> Any:
        return self.topo.replay

    def stored_count(self) -> int:
        """Sequences replay holds now."""
        return sum(int(h.local_object.shard.size_sequences) for h in self.replay.shards)

    def stored(self) -> list[tuple[dict[str, np.ndarray], int]]:
        """Every stored sequence in insert order: (window [T, ...] per field, real steps)."""
        out = []
        for handle in self.replay.shards:
            shard = handle.local_object.shard
            live = np.flatnonzero(shard.stamp >= 0)
            for slot in live[np.argsort(shard.stamp[live], kind="stable")]:
                data, mask, _ = shard.storage.read(np.array([slot]))
                out.append(({k: v[0] for k, v in data.items()}, int(mask[0].sum())))
        return out

    # -- stepping --------------------------------------------------------------------------
    def collect(self, segments: int = 1, explore: bool = True) -> None:
        """Every collector plays `segments` segments (`actors.segment_steps` steps of each env)."""
        for _ in range(segments):
            for col in self.collectors:
                res = col.run_segment(self.env_steps, self.learner_role.updates, explore)
                self.env_steps += int(res["env_steps"])
                self.returns.extend(res["episodes"])

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        """A batch as the learner gets it (outside the rate limiter)."""
        s = self.replay.sample(batch_size, timeout=0.0, limited=False)
        if s is None:
            raise ValueError("replay holds nothing to sample yet: collect first")
        return dict(s.data, mask=s.mask, is_weight=s.is_weight)

    def train(self, updates: int, batch_size: int | None = None) -> list[dict[str, float]]:
        """`updates` learner updates on fresh batches, then publish the weights (collectors
        pull them at their next segment). Returns each update's metrics."""
        bs = batch_size or self.cfg.learner.batch_size
        out = [self.learner.update(self.sample(bs)).metrics for _ in range(updates)]
        self.learner_role.updates += updates
        self.learner_role.version += 1
        self.learner_role.publish()
        return out

    def close(self) -> None:
        self.topo.shutdown()
        for col in self.collectors:
            try:
                col.venv.close()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        if self._tmp is not None:
            self._tmp.cleanup()
