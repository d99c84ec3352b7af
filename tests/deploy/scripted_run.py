"""The live test's data source: a MetricsHub fed by a tiny scripted training loop.

Swap point: once a short real `wmdist train` run is cheap enough for this test, replace
`scripted_run` with a context manager that starts that run and yields a `Source` with its
exporter port (and `unhealthy_alerts = set()`, since a healthy run trips no alert).
"""
from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass, field
from typing import Iterator

from wmdist.telemetry.metrics import MetricsHub

SHARDS = ("0", "1")


@dataclass
class Source:
    port: int  # the wmdist exporter's port on 127.0.0.1
    unhealthy_alerts: set[str] = field(default_factory=set)  # alerts this source trips on purpose


def _tick(hub: MetricsHub, i: int) -> None:
    """Report i of a fake run: counters grow, gauges move, every label set appears."""
    s = hub.set
    s("wmdist_env_steps_total", 64 * i)
    s("wmdist_env_steps_per_second", 256.0)
    s("wmdist_learner_updates_total", 4 * i)
    s("wmdist_learner_updates_per_second", 16.0)
    s("wmdist_train_ratio", 0.5)
    for role in ("train", "eval"):
        s("wmdist_episodes_total", i // 4 + 1, role=role)
        s("wmdist_episode_return", 10.0 + i * 0.5, role=role)
        s("wmdist_episode_length", 100.0 + i, role=role)
    for name in ("total", "value", "policy", "reward"):
        s("wmdist_learner_loss", 1.0 / (1 + i), name=name)
    # Unhealthy on purpose: the NaN guard keeps skipping and the actors lag far behind.
    s("wmdist_learner_nan_skips_total", 5 * i)
    s("wmdist_weights_version", i)
    s("wmdist_weights_version_gap", 500)
    for shard in SHARDS:
        s("wmdist_replay_size_steps", 320 * i, shard=shard)
        s("wmdist_replay_inserts_total", 2 * i, shard=shard)
        s("wmdist_replay_samples_total", 3 * i, shard=shard)
        s("wmdist_replay_drops_total", i // 2, shard=shard, reason="stale_priority")
    s("wmdist_limiter_wait_seconds_total", 0.05 * i, side="insert")
    s("wmdist_limiter_wait_seconds_total", 0.1 * i, side="sample")
    s("wmdist_policy_lag_drops_total", i // 3)
    s("wmdist_reanalyzed_sequences_total", 8 * i)
    for role in ("collector", "learner", "reanalyzer", "evaluator", "replay"):
        s("wmdist_busy_seconds_total", 0.2 * i, role=role)
    for role in ("collector", "reanalyzer", "evaluator"):
        s("wmdist_actor_restarts_total", 1 if i > 3 else 0, role=role)


@contextlib.contextmanager
def scripted_run(period_s: float = 0.25) -> Iterator[Source]:
    """Serve a MetricsHub on loopback and feed it every `period_s` until the block ends."""
    hub = MetricsHub()
    hub.start()
    stop = threading.Event()

    def loop() -> None:
        i = 0
        while not stop.is_set():
            _tick(hub, i)
            i += 1
            stop.wait(period_s)

    t = threading.Thread(target=loop, name="scripted-run", daemon=True)
    t.start()
    try:
        yield Source(port=hub.port, unhealthy_alerts={"WmdistWeightVersionGapHigh", "WmdistNanSkipsRising"})
    finally:
        stop.set()
        t.join(timeout=5)
        hub.close()
