"""Learner role: samples with prefetch, updates through the algorithm, publishes weights.

Driven by the driver in short slices (`train_for`), so checkpoints and stats never race
an update. A background thread keeps `learner.prefetch` batches sampled ahead, so the
replay round trip overlaps compute; the queue is bounded.
"""
from __future__ import annotations

import math
import queue
import threading
import time
from typing import Any

import numpy as np

from wmdist.algos.base import NonFiniteLoss
from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.faults import root_cause, transient
from wmdist.runtime.roles.setup import build_algorithm, device_for, set_threads


class Prefetcher:
    """A daemon thread that keeps a bounded queue of sampled batches."""

    def __init__(self, replay: Any, batch_size: int, depth: int, timeout: float) -> None:
        self.replay, self.batch_size, self.timeout = replay, batch_size, timeout
        self.queue: queue.Queue = queue.Queue(maxsize=depth)
        self.stop_event = threading.Event()
        self.wait_seconds = 0.0
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._loop, name="prefetch", daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while not self.stop_event.is_set():
            t0 = time.monotonic()
            try:
                sample = self.replay.sample(self.batch_size, timeout=self.timeout)
            except Exception as err:  # noqa: BLE001 - surfaced to the learner loop
                self.error = err
                time.sleep(0.5)
                continue
            self.wait_seconds += time.monotonic() - t0
            if sample is None:
                continue
            while not self.stop_event.is_set():
                try:
                    self.queue.put(sample, timeout=0.2)
                    break
                except queue.Full:
                    continue

    def get(self, timeout: float) -> Any:
        try:
            return self.queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def close(self) -> None:
        self.stop_event.set()
        self.thread.join(timeout=5.0)


class LearnerRole:
    def __init__(self, cfg: RunConfig, spec: EnvSpec, replay: Any, broker: Any, threads: int = 1,
                 services: dict[str, list[Any]] | None = None) -> None:
        set_threads(threads)
        self.cfg, self.replay, self.broker = cfg, replay, broker
        self.device = device_for(cfg.learner.gpus)
        self.algo = build_algorithm(cfg, spec, cfg.run.seed)
        self.learner = self.algo.make_learner(self.device)
        if services:  # the actors of roles that serve the learner (`Role.serves_learner`), by role name
            self.learner.use_services(services)
        self.updates = 0
        self.version = 0
        self.nan_skips = 0
        self.nan_streak = 0
        self.sampled_sequences = 0
        self.busy_seconds = 0.0
        self._sums: dict[str, float] = {}
        self._counts: dict[str, int] = {}
        self.prefetcher: Prefetcher | None = None
        self.publish()

    def _ensure_prefetch(self) -> Prefetcher:
        if self.prefetcher is None:
            c = self.cfg.learner
            self.prefetcher = Prefetcher(self.replay, c.batch_size, c.prefetch, c.sample_timeout)
        return self.prefetcher

    def publish(self) -> int:
        """One `ray.put` per version (two when the evaluator gets its own weights); the broker
        hands the refs to every puller."""
        from wmdist.runtime.calls import get, is_local, put

        local = is_local(self.broker)
        box = [put(self.learner.get_weights(), local=local)]
        ev = self.learner.get_eval_weights()
        if ev is not None:
            box.append(put(ev, local=local))
        get(self.broker.publish.remote(self.version, box))
        self.replay.set_policy_version(self.version)  # replay drops data older than max_policy_lag
        return self.version

    def _record(self, metrics: dict[str, float]) -> None:
        for k, v in metrics.items():
            v = float(v)
            if math.isfinite(v):
                self._sums[k] = self._sums.get(k, 0.0) + v
                self._counts[k] = self._counts.get(k, 0) + 1

    def train_for(self, seconds: float, max_updates: int = 0) -> dict:
        """Update for about `seconds` (or until `max_updates` in total); return stats."""
        pf = self._ensure_prefetch()
        if pf.error is not None:
            err, pf.error = pf.error, None
            if transient(err):  # the store is restarting: the driver asks again shortly
                return self._stats("replay_down", f"sampling failed: {root_cause(err)}")
            return self._stats("error", f"sampling failed: {err}")
        end = time.monotonic() + seconds
        status, message = "ok", ""
        while time.monotonic() < end and (max_updates <= 0 or self.updates < max_updates):
            sample = pf.get(timeout=min(0.2, max(end - time.monotonic(), 0.01)))
            if sample is None:
                continue
            t0 = time.monotonic()
            batch = dict(sample.data, mask=sample.mask, is_weight=sample.is_weight)
            self.sampled_sequences += len(sample.mask)
            try:
                result = self.learner.update(batch)
            except NonFiniteLoss as err:
                self.nan_skips += 1
                self.nan_streak += 1
                self.busy_seconds += time.monotonic() - t0
                if self.nan_streak >= self.cfg.learner.max_nan_streak:
                    status = "nan_stop"
                    message = (f"{self.nan_streak} non-finite updates in a row (last: {err}); "
                               f"stopping - lower the learning rate or check the data")
                    break
                continue
            self.nan_streak = 0
            self.updates += 1
            self._record(result.metrics)
            # uniform sampling never reads priorities: skip the shard call (and the draw-pool refresh it forces)
            if result.priorities is not None and self.cfg.replay.sampler == "prioritized":
                self.replay.update_priorities(sample.keys, sample.stamps, np.asarray(result.priorities, np.float64))
            if self.updates % self.cfg.learner.publish_every == 0:
                self.version += 1
                self.publish()
            self.busy_seconds += time.monotonic() - t0
        return self._stats(status, message)

    def _stats(self, status: str, message: str) -> dict:
        losses = {k: self._sums[k] / self._counts[k] for k in self._sums}
        self._sums, self._counts = {}, {}
        pf = self.prefetcher
        return {"status": status, "message": message, "updates": self.updates, "version": self.version,
                "nan_skips": self.nan_skips, "sampled_sequences": self.sampled_sequences,
                "busy_seconds": self.busy_seconds, "sample_wait_seconds": pf.wait_seconds if pf else 0.0,
                "losses": losses}

    # -- checkpoints ---------------------------------------------------------------------
    def state(self) -> dict:
        return {"learner": self.learner.state_dict(), "updates": self.updates, "version": self.version,
                "nan_skips": self.nan_skips, "sampled_sequences": self.sampled_sequences}

    def weights(self) -> tuple[int, dict]:
        """The weights a checkpoint keeps: the evaluator's when it gets its own."""
        ev = self.learner.get_eval_weights()
        return self.version, self.learner.get_weights() if ev is None else ev

    def load(self, state: dict, min_version: int = 0) -> int:
        """Restore a checkpoint's state; weights are published as version >= `min_version` (a
        learner restarted mid-run must publish newer versions than its dead predecessor did,
        or the broker and collectors would keep the old ones)."""
        self.learner.load_state_dict(state["learner"])
        self.updates = int(state["updates"])
        self.version = max(int(state["version"]), min_version)
        self.nan_skips = int(state.get("nan_skips", 0))
        self.sampled_sequences = int(state.get("sampled_sequences", 0))
        self.publish()
        return self.version

    def publish_from(self, min_version: int) -> int:
        """Publish these weights as version >= `min_version` (a learner started afresh mid-run)."""
        self.version = max(self.version, min_version)
        return self.publish()

    def close(self) -> None:
        if self.prefetcher is not None:
            self.prefetcher.close()
            self.prefetcher = None

    def ping(self) -> bool:
        return True
