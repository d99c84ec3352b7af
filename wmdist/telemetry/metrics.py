"""wmdist metrics: every metric is declared once in `METRICS`, served by one exporter.

The training driver gathers running totals from every actor about once a second and
calls `MetricsHub.set(name, value, **labels)`. Counters are *set* to their running totals
(the actors own the counts), which prometheus_client's own Counter cannot do, so the hub
exports through a custom Collector that renders whatever was last set.

    hub = MetricsHub()                      # 127.0.0.1, free port
    hub.start(); print(hub.url)             # http://127.0.0.1:PORT/metrics
    hub.set("wmdist_env_steps_total", 12345)
    hub.set("wmdist_episode_return", 21.0, role="eval")
    hub.snapshot()  # {"wmdist_env_steps_total": 12345.0, "wmdist_episode_return{role=eval}": 21.0, ...}
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Iterator, Mapping

from prometheus_client import start_http_server
from prometheus_client.core import CollectorRegistry, CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector



@dataclass(frozen=True)
class MetricDef:
    """One declared metric: Prometheus type, help text, label names (and allowed values)."""

    type: str  # "counter" (name ends in _total, value never negative) or "gauge"
    help: str
    labels: tuple[str, ...] = ()
    allowed: Mapping[str, tuple[str, ...]] = field(default_factory=dict)  # label -> values


def _c(help: str, *labels: str, **allowed: tuple[str, ...]) -> MetricDef:
    return MetricDef("counter", help, labels, allowed)


def _g(help: str, *labels: str, **allowed: tuple[str, ...]) -> MetricDef:
    return MetricDef("gauge", help, labels, allowed)


_TRAIN_EVAL = ("train", "eval")

# The one table of metric names. Counters end in `_total`; units in the name (seconds, steps).
METRICS: dict[str, MetricDef] = {
    # acting
    "wmdist_env_steps_total": _c("Environment steps taken by all collectors."),
    "wmdist_env_steps_per_second": _g("Environment steps per second over the last 30 s (wmdist.runtime.rates)."),
    "wmdist_episodes_total": _c("Episodes finished, by role.", "role", role=_TRAIN_EVAL),
    "wmdist_episode_return": _g("Mean return of the episodes finished in the last interval.", "role", role=_TRAIN_EVAL),
    "wmdist_episode_length": _g("Mean length in steps of the episodes finished in the last interval.", "role", role=_TRAIN_EVAL),
    # learning
    "wmdist_learner_updates_total": _c("Learner updates applied."),
    "wmdist_learner_updates_per_second": _g("Learner updates per second over the last 30 s (wmdist.runtime.rates)."),
    "wmdist_learner_loss": _g("Latest value of each learner loss or scalar the algorithm reports.", "name"),
    "wmdist_learner_nan_skips_total": _c("Updates skipped because the loss was not finite."),
    "wmdist_train_ratio": _g("Replayed steps per environment step, measured (the limiter's target is in the config)."),
    # replay
    "wmdist_replay_size_steps": _g("Steps held by a replay shard.", "shard"),
    "wmdist_replay_inserts_total": _c("Sequences inserted into a replay shard.", "shard"),
    "wmdist_replay_samples_total": _c("Sequences sampled from a replay shard.", "shard"),
    "wmdist_replay_drops_total": _c("Items a replay shard dropped, by reason (nothing is dropped silently).", "shard", "reason"),
    "wmdist_limiter_wait_seconds_total": _c(
        "Seconds spent blocked by the rate limiter, by side.", "side", side=("insert", "sample")
    ),
    # weights
    "wmdist_weights_version": _g("Latest weight version the learner published."),
    "wmdist_weights_version_gap": _g("Published version minus the oldest version still acting."),
    "wmdist_policy_lag_drops_total": _c("Sequences dropped for exceeding the maximum policy lag."),
    "wmdist_reanalyzed_sequences_total": _c("Sequences whose targets a reanalyzer refreshed."),
    # processes
    # role: a name from the run's table of roles (wmdist/runtime/table.py), an algorithm's own roles too
    "wmdist_actor_restarts_total": _c("Actor restarts after a failure, by role.", "role"),
    "wmdist_busy_seconds_total": _c("Seconds each role spent working (not waiting), summed over its actors.", "role"),
}


def _check_table(table: Mapping[str, MetricDef]) -> None:
    """Conventions the table must keep (checked at import so a bad edit fails loudly)."""
    for name, d in table.items():
        if not name.startswith("wmdist_"):
            raise ValueError(f"metric {name!r}: names start with 'wmdist_'")
        if d.type not in ("counter", "gauge"):
            raise ValueError(f"metric {name!r}: type must be counter or gauge, got {d.type!r}")
        if (d.type == "counter") != name.endswith("_total"):
            raise ValueError(f"metric {name!r}: counters, and only counters, end in '_total'")
        if set(d.allowed) - set(d.labels):
            raise ValueError(f"metric {name!r}: allowed values given for undeclared labels")


_check_table(METRICS)

_LabelKey = tuple[str, ...]  # label values in declared order


def snapshot_key(name: str, /, **labels: str) -> str:
    """The flat key `snapshot()` uses: `name` or `name{a=x,b=y}` (labels in declared order)."""
    d = METRICS.get(name)
    order = d.labels if d is not None else tuple(sorted(labels))
    if not labels:
        return name
    return name + "{" + ",".join(f"{k}={labels[k]}" for k in order) + "}"


class MetricsHub:
    """Holds the latest value of every declared metric and serves them over HTTP.

    Thread-safe: `set` may be called from the driver loop while the HTTP thread scrapes.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"metrics port must be in [0, 65535], got {port}")
        self._host = host
        self._want_port = int(port)
        self._lock = threading.Lock()
        self._values: dict[str, dict[_LabelKey, float]] = {n: {} for n in METRICS}
        for name, d in METRICS.items():
            if not d.labels:  # unlabelled series exist from the start, at 0
                self._values[name][()] = 0.0
        self._server = None
        self._thread: threading.Thread | None = None
        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(_HubCollector(self))

    # -- values ---------------------------------------------------------------------
    def set(self, name: str, value: float, /, **labels: str) -> None:
        """Set a metric's value (counters: their running total). Raises ValueError if undeclared.

        `name` and `value` are positional-only so a label may be called `name`
        (`set("wmdist_learner_loss", 0.3, name="value")`).
        """
        d = METRICS.get(name)
        if d is None:
            raise ValueError(f"undeclared metric {name!r}: declare it in wmdist.telemetry.metrics.METRICS")
        if set(labels) != set(d.labels):
            raise ValueError(f"metric {name!r} takes labels {list(d.labels)}, got {sorted(labels)}")
        key = tuple(str(labels[k]) for k in d.labels)
        for k, v in zip(d.labels, key):
            ok = d.allowed.get(k)
            if ok is not None and v not in ok:
                raise ValueError(f"metric {name!r}: label {k}={v!r} not one of {list(ok)}")
        is_number = isinstance(value, (int, float)) or hasattr(value, "__float__")  # numpy scalars too
        if isinstance(value, bool) or isinstance(value, str) or not is_number:
            raise ValueError(f"metric {name!r}: value must be a number, got {type(value).__name__}")
        v = float(value)
        if d.type == "counter" and not (math.isfinite(v) and v >= 0):
            raise ValueError(f"counter {name!r} must be a finite total >= 0, got {v}")
        with self._lock:
            self._values[name][key] = v

    def snapshot(self) -> dict[str, float]:
        """Flat `{"name{label=value}": value}` of everything set so far (for JSONL and the console)."""
        out: dict[str, float] = {}
        with self._lock:
            for name, series in self._values.items():
                labels = METRICS[name].labels
                for key, v in series.items():
                    out[snapshot_key(name, **dict(zip(labels, key)))] = v
        return out

    def _families(self) -> Iterator[Metric]:
        with self._lock:
            items = [(n, dict(s)) for n, s in self._values.items()]
        for name, series in items:
            d = METRICS[name]
            if d.type == "counter":
                # prometheus_client appends `_total` to the sample name itself.
                fam: Metric = CounterMetricFamily(name[: -len("_total")], d.help, labels=d.labels)
            else:
                fam = GaugeMetricFamily(name, d.help, labels=d.labels)
            for key, v in series.items():
                fam.add_metric(list(key), v)
            yield fam

    # -- server ---------------------------------------------------------------------
    def start(self) -> None:
        """Serve /metrics on host:port in a daemon thread (port 0 picks a free one)."""
        if self._server is not None:
            raise RuntimeError("MetricsHub already started")
        self._server, self._thread = start_http_server(self._want_port, addr=self._host, registry=self.registry)

    @property
    def port(self) -> int:
        if self._server is None:
            raise RuntimeError("MetricsHub not started: call start() first")
        return int(self._server.server_port)

    @property
    def url(self) -> str:
        host = f"[{self._host}]" if ":" in self._host else self._host
        return f"http://{host}:{self.port}/metrics"

    def close(self) -> None:
        """Stop serving (idempotent)."""
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            if self._thread is not None:
                self._thread.join(timeout=5)
            self._server, self._thread = None, None

    def __enter__(self) -> "MetricsHub":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _HubCollector(Collector):
    """Renders the hub's current values at every scrape."""

    def __init__(self, hub: MetricsHub) -> None:
        self._hub = hub

    def collect(self) -> Iterator[Metric]:
        return self._hub._families()
