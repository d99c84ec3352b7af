"""Soak benchmark: train with faults injected at random, then check the replay's accounting.

    wmdist bench soak --json                 # 30 minutes, a fault every 2-5 minutes
    wmdist bench soak --json --quick         # 3 minutes, a fault every 20-60 seconds

Runs `configs/muzero_reanalyze_cartpole.yaml` (a collector, a learner, a reanalyzer) on an
embedded local Ray with the redis backend (`appendfsync always`), a checkpoint a minute. A
fault thread kills, in random order, the collector's, the reanalyzer's, the learner's, the
weight broker's or the rate limiter's process, or the private redis-server; the driver
and Ray bring each back (the learner from the latest checkpoint, `learner.max_restarts`
set high enough for every fault). At the end every sequence a collector saw acknowledged
must be in replay or counted as evicted, and the train ratio (sampled / inserted sequences)
is compared with `replay.samples_per_insert` (a restarted limiter counts from zero: the
ratio is summed over the stretches between its restarts). Not part of `wmdist bench all`
(it is long): one JSON line per fault, and one summary line.
"""
from __future__ import annotations

import os
import random
import signal
import tempfile
import threading
from pathlib import Path
from typing import Iterator

CONFIG = str(Path(__file__).resolve().parents[2] / "configs" / "muzero_reanalyze_cartpole.yaml")
WARMUP_SHARE = 0.1  # the ratio is judged after this share of the run (the limiter's min_size fill)
FAULTS = ("collector", "reanalyzer", "learner", "broker", "limiter", "redis")


def _actor(topo, kind: str):
    """The actor a fault kills (looked up at the time: a restarted learner is a new actor)."""
    return {"collector": lambda: topo.collectors[0], "reanalyzer": lambda: topo.reanalyzers[0],
            "learner": lambda: topo.learner, "broker": lambda: topo.broker,
            "limiter": lambda: topo.replay.limiter}[kind]()


def run(quick: bool = False, minutes: float | None = None, config: str = CONFIG, seed: int = 0) -> Iterator[dict]:
    import ray

    from wmdist.config.loader import load_config
    from wmdist.runtime.driver import Counters, Driver
    from wmdist.runtime.preflight import check_env_and_algo
    from wmdist.runtime.topology import build, start_ray

    minutes = minutes or (3.0 if quick else 30.0)
    gap = (20.0, 60.0) if quick else (120.0, 300.0)  # seconds between faults
    tmp = Path(tempfile.mkdtemp(prefix="wmdist-soak-"))
    cfg = load_config(config, [f"run.dir={tmp}", f"run.max_minutes={minutes}", "run.max_env_steps=0",
                               "replay.backend=redis", "replay.redis_appendfsync=always", "metrics.enabled=false",
                               "checkpoint.every_seconds=60", "eval.every_seconds=0", "learner.max_restarts=1000"])
    spec, algo = check_env_and_algo(cfg)
    start_ray(cfg)
    topo = build(cfg, spec, tmp, algo.step_fields())
    events: list[dict] = []
    counts: list[tuple[float, float, float]] = []  # (elapsed, sampled, inserted) sequences, from the limiter

    class Counting(Driver):
        acked = 0  # sequences collectors were told replay stored

        def _handle(self, kind, i, res):
            if kind == "collector":
                self.acked += int(res.get("inserted", 0))
            super()._handle(kind, i, res)

        def tick(self, force_plot: bool = False) -> dict:
            snap = super().tick(force_plot)
            r = snap.get("replay") or {}
            if r.get("limiter_inserted"):
                counts.append((self.elapsed(), r["limiter_sampled"], r["limiter_inserted"]))
            return snap

    driver = Counting(topo, Counters())
    rng = random.Random(seed)
    stop = threading.Event()

    def inject() -> None:
        while not stop.wait(rng.uniform(*gap)):
            kind = rng.choice(FAULTS)
            try:
                if kind == "redis":
                    os.kill(topo.replay._server.proc.pid, signal.SIGKILL)
                else:  # the process dies as if SIGKILLed; Ray restarts what is restartable
                    ray.kill(_actor(topo, kind), no_restart=False)
            except Exception as err:  # noqa: BLE001 - report and go on
                events.append({"t": round(driver.elapsed(), 1), "fault": kind, "error": str(err)[:200]})
                continue
            events.append({"t": round(driver.elapsed(), 1), "fault": kind})

    thread = threading.Thread(target=inject, daemon=True)
    thread.start()
    try:
        result = driver.run()
        stop.set()
        stats = topo.replay.stats()
    finally:
        stop.set()
        topo.shutdown()
    for e in events:
        yield {"case": "fault", **e}
    target = cfg.replay.samples_per_insert
    ratio, windows = _ratios(counts, WARMUP_SHARE * minutes * 60, window=30.0 if quick else 120.0)
    stored, evicted, inserts = (int(stats.get(k, 0)) for k in ("size_sequences", "drops_evicted", "inserts"))
    yield {
        "case": "summary", "minutes": minutes, "status": result.status, "message": result.message,
        "faults": {k: sum(1 for e in events if e["fault"] == k and "error" not in e)
                   for k in FAULTS},
        "restarts": result.counters.restarts, "env_steps": result.counters.env_steps,
        "updates": result.counters.updates, "acked": driver.acked, "inserts": inserts, "stored": stored,
        "evicted": evicted, "unaccounted": inserts - stored - evicted,
        "acked_all_accounted": driver.acked <= stored + evicted,
        "train_ratio_target": target, "train_ratio_after_warmup": ratio and round(ratio, 2),
        "train_ratio_rel_error": ratio and target and round(ratio / target - 1, 4),
        "train_ratio_windows": [round(w, 1) for w in windows],
        "train_ratio_windows_max_rel_error": round(max(abs(w / target - 1) for w in windows), 4)
        if windows and target else None,
        "drops": {k: v for k, v in stats.items() if k.startswith("drops_") and v},
    }


def _ratios(counts: list[tuple[float, float, float]], start: float, window: float) -> tuple[float | None, list[float]]:
    """Sampled per inserted sequence after `start` seconds (the warm-up fill excluded), overall
    and in consecutive windows of about `window` seconds. A restarted limiter counts from zero
    again: its counts going down end a stretch, and the stretches are summed (a window never
    spans a restart)."""
    judged = [c for c in counts if c[0] >= start]
    windows, sampled, inserted = [], 0.0, 0.0
    for stretch in _stretches(judged):
        a = stretch[0]
        for b in stretch[1:]:
            if b[0] - a[0] >= window:
                r = _ratio(a, b)
                if r is not None:
                    windows.append(r)
                a = b
        sampled += stretch[-1][1] - stretch[0][1]
        inserted += stretch[-1][2] - stretch[0][2]
    return (sampled / inserted if inserted > 0 else None), windows


def _stretches(counts: list[tuple[float, float, float]]) -> list[list[tuple[float, float, float]]]:
    """`counts` cut where a count went down (the limiter restarted)."""
    out: list[list] = []
    for c in counts:
        if out and c[1] >= out[-1][-1][1] and c[2] >= out[-1][-1][2]:
            out[-1].append(c)
        else:
            out.append([c])
    return out


def _ratio(a: tuple[float, float, float], b: tuple[float, float, float]) -> float | None:
    return (b[1] - a[1]) / (b[2] - a[2]) if b[2] > a[2] else None
