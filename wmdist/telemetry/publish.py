"""Driver-side telemetry: the driver's snapshot -> Prometheus metrics and the console view."""
from __future__ import annotations

import re
from pathlib import Path
from typing import IO

from wmdist.config.schema import RunConfig

def publish(hub, snap: dict) -> None:
    """Set every wmdist_ metric from one driver snapshot (counters are set to totals)."""
    s = hub.set
    s("wmdist_env_steps_total", snap["env_steps"])
    s("wmdist_env_steps_per_second", snap["env_steps_per_second"])
    s("wmdist_episodes_total", snap["episodes"], role="train")
    s("wmdist_episodes_total", snap["eval_episodes"], role="eval")
    for role in ("train", "eval"):
        if snap.get(f"{role}_return") is not None:
            s("wmdist_episode_return", snap[f"{role}_return"], role=role)
        if snap.get(f"{role}_length") is not None:
            s("wmdist_episode_length", snap[f"{role}_length"], role=role)
    s("wmdist_learner_updates_total", snap["updates"])
    s("wmdist_learner_updates_per_second", snap["updates_per_second"])
    for name, value in snap["losses"].items():
        s("wmdist_learner_loss", value, name=name)
    s("wmdist_learner_nan_skips_total", snap["nan_skips"])
    s("wmdist_weights_version", snap["version"])
    s("wmdist_weights_version_gap", snap["version_gap"])
    s("wmdist_reanalyzed_sequences_total", snap["reanalyzed"])
    # one series per role of the run's table (the driver's counters hold every role that works)
    for role, seconds in snap["busy"].items():
        s("wmdist_busy_seconds_total", seconds, role=role)
    for role, n in snap["restarts"].items():
        if role != "redis":  # the private redis-server is a service, not an actor
            s("wmdist_actor_restarts_total", n, role=role)
    replay = snap.get("replay") or {}
    s("wmdist_policy_lag_drops_total", replay.get("drops_policy_lag", 0))
    # measured train ratio: learner-sampled sequences per inserted sequence (replay.samples_per_insert);
    # the limiter's counts leave out the reanalyzers' unlimited draws
    s("wmdist_train_ratio", replay.get("limiter_sampled", 0) / max(replay.get("limiter_inserted", 0), 1))
    for key, value in replay.items():
        m = _SHARD_KEY.match(key)
        if not m:
            continue
        shard, what = m.group(1), m.group(2)
        if what in _SHARD_METRICS:
            s(_SHARD_METRICS[what], value, shard=shard)
        elif what.startswith("drops_"):
            s("wmdist_replay_drops_total", value, shard=shard, reason=what[len("drops_"):])
    s("wmdist_limiter_wait_seconds_total", replay.get("insert_wait_seconds", 0.0), side="insert")
    s("wmdist_limiter_wait_seconds_total", replay.get("sample_wait_seconds", 0.0), side="sample")


_SHARD_KEY = re.compile(r"^shard(\d+)_(\w+)$")
_SHARD_METRICS = {"size_steps": "wmdist_replay_size_steps", "inserts": "wmdist_replay_inserts_total",
                  "samples": "wmdist_replay_samples_total"}


class Telemetry:
    """Owns the metrics exporter and the console progress view of one training run."""

    def __init__(self, cfg: RunConfig, run_dir: Path, out: IO[str], hub=None) -> None:
        """`hub`: an exporter already bound (`wmdist train` binds it before Ray starts, so a busy
        port is a one-line error); None starts one here when metrics are enabled."""
        from wmdist.telemetry.metrics import MetricsHub
        from wmdist.telemetry.progress import Progress

        self.hub = hub
        if self.hub is None and cfg.metrics.enabled:
            self.hub = MetricsHub(host=cfg.metrics.host, port=cfg.metrics.port)
            self.hub.start()
        if self.hub is not None:
            (run_dir / "metrics_port").write_text(str(self.hub.port))
            print(f"wmdist: metrics at {self.hub.url}", file=out, flush=True)
        self.progress = Progress(cfg.run.max_env_steps, cfg.run.max_minutes, stream=out)
        self.tb = None
        if cfg.metrics.tensorboard:
            from wmdist.telemetry.tensorboard import TensorBoardLog

            self.tb = TensorBoardLog(run_dir)

    def record(self, record: dict) -> None:
        """One metrics.jsonl record, mirrored into TensorBoard."""
        if self.tb is not None:
            self.tb.record(record)

    def curve(self, png_path: Path, env_steps: int) -> None:
        """The redrawn learning curve, as a TensorBoard image."""
        if self.tb is not None and png_path.is_file():
            self.tb.image("learning_curve", png_path, env_steps)

    def update(self, snap: dict) -> None:
        if self.hub is not None:
            publish(self.hub, snap)
        self.progress.update(snap)

    def close(self) -> None:
        self.progress.close()
        if self.tb is not None:
            self.tb.close()
        if self.hub is not None:
            self.hub.close()
