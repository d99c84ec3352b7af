"""Reanalyzer role: sample stored sequences, rerun the algorithm's reanalyze with the
latest weights, write fresh targets back (dropped by replay if the item changed since)."""
from __future__ import annotations

import time
from typing import Any

from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.priority import lower_priority
from wmdist.runtime.roles.setup import build_algorithm, device_for, in_ray_actor, process_tag, set_threads
from wmdist.runtime.roles.weights import pull


class ReanalyzerRole:
    def __init__(self, cfg: RunConfig, spec: EnvSpec, index: int, replay: Any, broker: Any, threads: int = 1) -> None:
        set_threads(threads)
        # its own process only (the local runner runs every role in one); before torch starts its pool
        self.by = cfg.reanalyze.nice if in_ray_actor() else 0
        self.nice = lower_priority(self.by)
        self.tag = process_tag()  # who answers (the driver counts restarts by it)
        self.cfg, self.replay, self.broker = cfg, replay, broker
        algo = build_algorithm(cfg, spec, cfg.run.seed + 7_777 + index)
        self.reanalyzer = algo.make_reanalyzer(device_for(cfg.reanalyze.gpus))
        if self.reanalyzer is None:
            raise ValueError(f"algorithm {cfg.algo_name!r} has no reanalyze step; set reanalyze.num=0")
        self.version = -1
        self.done = 0

    def run_job(self) -> dict:
        """One batch: returns how many sequences got fresh targets."""
        t0 = time.monotonic()
        if self.by:  # the thread Ray runs calls on may not be the constructor's
            lower_priority(self.by, base=self.nice - self.by)
        version, weights = pull(self.broker, self.version)
        if weights is not None:
            self.reanalyzer.set_weights(weights, version)
            self.version = version
        sample = self.replay.sample(self.cfg.reanalyze.batch_size, timeout=1.0, limited=False)
        if sample is None:
            return {"reanalyzed": 0, "busy_seconds": time.monotonic() - t0, "version": self.version,
                **self.tag}
        batch = dict(sample.data, mask=sample.mask, is_weight=sample.is_weight)
        if sample.age is not None:  # transitions stored after each step (EfficientZero's correction)
            batch["age"] = sample.age
        fields = self.reanalyzer.reanalyze(batch)
        self.replay.write_back(sample.keys, sample.stamps, fields)
        n = len(sample.mask)
        self.done += n
        return {"reanalyzed": n, "busy_seconds": time.monotonic() - t0, "version": self.version,
                **self.tag}

    def ping(self) -> bool:
        return True
