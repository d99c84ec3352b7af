"""The training loop of the driver process: keeps every actor busy, gathers their stats,
serves metrics, prints progress, writes logs, curves and checkpoints, and stops cleanly.

Each actor works in short calls (a collector segment, a learner slice, a reanalyze job,
an evaluation); the driver re-issues a call as soon as the previous one returns. A call
that fails because its actor died is re-issued (Ray restarts the actor, which pulls the
current weights in its constructor) and a restart is counted when a new process answers;
an actor whose restarts are used up ends the run with a one-line error, and the learner
dying ends the run with a message that names --resume.
"""
from __future__ import annotations

import collections
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from wmdist.runtime.calls import get, wait
from wmdist.runtime.checkpoint import save_checkpoint
from wmdist.runtime.faults import death as _death
from wmdist.runtime.faults import died as _died
from wmdist.runtime.faults import failed_to_start as _failed_to_start
from wmdist.runtime.faults import one_line as _one_line
from wmdist.runtime.faults import root_cause as _root_cause
from wmdist.runtime.faults import transient
from wmdist.runtime.rates import RATE_WINDOW_SECONDS, WindowRates
from wmdist.runtime.table import LEARNER_SLICE_SECONDS, LOCAL_LEARNER_SLICE_SECONDS, LOOP, PACED, PERIODIC, BUILTIN_NAMES, Role
from wmdist.runtime.topology import Topology

__all__ = ["LEARNER_SLICE_SECONDS", "Counters", "Driver", "RunResult"]

RETRY_SECONDS = 0.5  # wait before re-asking an actor whose process died
REPLAY_RETRY_SECONDS = 1.0  # wait before re-asking a role that could not reach the replay store
# A replay store unreachable this long ends the run (one line naming --resume); shorter outages
# (a redis-server restarted by the driver or by hand) are ridden out.
REPLAY_OUTAGE_SECONDS = 60.0
SERVICE_CHECK_SECONDS = 1.0  # how often the driver looks at its private redis-server

log = logging.getLogger("wmdist")  # the run's log file (train.py); never the console
log.addHandler(logging.NullHandler())  # no file attached (tests, benchmarks): say nothing


_ACTING = tuple(n for n in BUILTIN_NAMES if n not in ("replay", "limiter", "learner"))


@dataclass
class Counters:
    """Run totals that survive a resume (saved in every checkpoint)."""

    env_steps: int = 0
    episodes: int = 0
    updates: int = 0
    version: int = 0
    elapsed_seconds: float = 0.0
    reanalyzed: int = 0
    sampled_sequences: int = 0
    nan_skips: int = 0
    eval_episodes: int = 0
    # per role of the table (an algorithm's own roles join when they first report), and "redis"
    restarts: dict = field(default_factory=lambda: {**{r: 0 for r in _ACTING}, "redis": 0})
    busy: dict = field(default_factory=lambda: {r: 0.0 for r in ("learner", *_ACTING)})

    def as_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, d: dict) -> "Counters":
        c = cls()
        for k, v in d.items():
            if hasattr(c, k):
                setattr(c, k, v)
        return c


@dataclass
class RunResult:
    status: str  # "done" | "interrupted" | "nan_stop" | "learner_failed" | "error"
    message: str
    counters: Counters


class Driver:
    def __init__(self, topo: Topology, counters: Counters, on_tick: Callable[[dict], None] | None = None,
                 log_path: Path | None = None, plot: Callable[[], None] | None = None,
                 on_record: Callable[[dict], None] | None = None) -> None:
        """`on_tick(snapshot)` about every `run.log_every_seconds`; `on_record(record)` for each
        line written to metrics.jsonl (TensorBoard mirrors them); `plot()` redraws the curve."""
        self.on_record = on_record
        self.topo, self.c = topo, counters
        self.cfg = topo.cfg
        self.roles: dict[str, Role] = {r.name: r for r in topo.roles if r.call is not None}
        self.learner_slice = LOCAL_LEARNER_SLICE_SECONDS if topo.local else LEARNER_SLICE_SECONDS
        self.on_tick, self.log_path, self.plot = on_tick, log_path, plot
        self.train_returns: collections.deque = collections.deque(maxlen=100)
        self.train_lengths: collections.deque = collections.deque(maxlen=100)
        self.eval_return: float | None = None
        self.final_weights: tuple | None = None  # (version, weights) a stop-at-judge evaluation kept
        self.eval_length: float | None = None
        self.losses: dict[str, float] = {}
        self.collector_versions: dict[int, int] = {}
        self.limiter_blocked = 0
        self.inflight: dict[Any, tuple[str, int]] = {}
        self.pids: dict[tuple[str, int], int] = {}
        self.retry_at: dict[tuple[str, int], float] = {}  # calls to re-issue once a dead actor may be back
        self.deaths: collections.Counter = collections.Counter()  # (kind, i) -> times its process died
        self.coming_back: set[tuple[str, int]] = set()  # a call died; not heard from since
        self.stop_reason: tuple[str, str] | None = None
        self.t_start = time.monotonic()
        self.elapsed0 = counters.elapsed_seconds
        self.last_tick = self.last_plot = self.last_ckpt = self.last_eval = time.monotonic()
        self.last_eval_steps = counters.env_steps
        self.rates = {"env_steps": 0.0, "updates": 0.0}
        self._rates = WindowRates(RATE_WINDOW_SECONDS, time.monotonic(), self._rate_counts())
        self.last_snapshot: dict = {}
        self.outage_since: float | None = None  # when a role first found the replay store unreachable
        self.last_service_check = time.monotonic()
        self.checkpoint_error: str | None = None  # why the last checkpoint could not be written
        self.last_checkpoint: Path | None = None

    def request_stop(self, reason: str = "stopped on request") -> None:
        """Ask the loop (possibly running in another thread) to stop at its next turn."""
        if self.stop_reason is None:
            self.stop_reason = ("done", reason)

    # -- calls ---------------------------------------------------------------------------
    def _issue(self, kind: str, i: int) -> None:
        """Issue `kind`'s call on its actor i (the table entry says which call)."""
        role = self.roles[kind]
        self.inflight[role.call(self.topo.actors[kind][i], self)] = (kind, i)

    def _reanalyze_due(self) -> bool:
        """Pace reanalyzers: fresh targets for about `reanalyze.fraction` of learner samples."""
        want = self.cfg.reanalyze.fraction * max(self.c.sampled_sequences, self.cfg.learner.batch_size)
        return self.c.reanalyzed < want

    def _handle(self, kind: str, i: int, res: dict) -> None:
        self._note_process(kind, i, res)
        role = self.roles[kind]
        if role.handle is not None:
            role.handle(self, i, res)
        else:
            from wmdist.runtime.table import answer_busy

            answer_busy(self, kind, res)

    def record_eval(self, res: dict) -> None:
        """An evaluation's episodes: the eval figures and a line in metrics.jsonl."""
        self.c.eval_episodes += len(res["returns"])
        self.eval_return = float(np.mean(res["returns"]))
        self.eval_length = float(np.mean(res["lengths"]))
        # eval_min: the worst episode (board games: < 0 means the agent lost a game); any other
        # numbers the evaluator reports (e.g. lines lost over a whole game tree) go in as well
        extra = {k: v for k, v in res.items() if k.startswith("eval_") and isinstance(v, (int, float))}
        self._log({"kind": "eval", "eval_return": self.eval_return, "eval_length": self.eval_length,
                   "eval_min": float(np.min(res["returns"])), "eval_version": res["version"], **extra})
        if res.get("judged_weights") is not None and self.stop_reason is None:
            self.final_weights = (res["version"], res["judged_weights"])
            self.stop_reason = ("done", f"the judge found {res['eval_lost_lines']} lost lines of {res['eval_lines']} "
                                        f"(weights v{res['version']} kept)")

    def maybe_checkpoint(self) -> None:
        every = self.cfg.checkpoint.every_seconds
        if every > 0 and time.monotonic() - self.last_ckpt >= every:
            self.checkpoint()

    def _note_process(self, kind: str, i: int, res: dict) -> None:
        """Count a restart when a new process answers for (kind, i): a pid other than the last
        one seen, or a first answer from a process Ray started as a replacement (an actor killed
        during start-up fails no call: its queued calls run in the replacement)."""
        key, pid = (kind, i), res.get("pid")
        if pid is not None and self.pids.get(key) != pid:
            if key in self.pids or res.get("restarted"):
                self.c.restarts[kind] = self.c.restarts.get(kind, 0) + 1
                if key not in self.coming_back:  # a death no failed call told us of
                    self.deaths[key] += 1
            self.pids[key] = pid
        self.coming_back.discard(key)

    def _restarts_used_up(self, kind: str, i: int) -> bool:
        """Record a death of (kind, i); True once Ray will not bring it back (only collectors
        have a finite `actors.max_restarts`; calls to a dead actor fail at once, so this stops a
        busy loop of retries)."""
        if (kind, i) not in self.coming_back:  # a retry failing before it is back is the same death
            self.deaths[(kind, i)] += 1
            self.coming_back.add((kind, i))
        limit = self.roles[kind].max_restarts(self.cfg)
        return limit >= 0 and self.deaths[(kind, i)] > limit

    def _restart_learner(self, err: BaseException) -> bool:
        """The learner's process died (Ray does not restart it: a new process would start from
        random weights). Start a new one from the latest checkpoint, or afresh before the first,
        publishing versions past the dead one's; replay, collectors and counters go on. False
        when `learner.max_restarts` are used up (or on the Ray-free local runner)."""
        from wmdist.runtime.checkpoint import latest_checkpoint, load_learner_state

        used = self.c.restarts.get("learner", 0)
        if self.topo.local or used >= self.cfg.learner.max_restarts:
            return False
        ckpt = latest_checkpoint(self.topo.run_dir)
        log.warning("the learner's process died (%s); starting a new one from %s", _death(err),
                    ckpt.name if ckpt is not None else "scratch (no checkpoint yet)")
        try:
            newest = int(get(self.topo.broker.current_version.remote(), timeout=60))
            learner = self.topo.replace("learner", 0)
            if ckpt is not None:
                get(learner.load.remote(load_learner_state(ckpt), newest + 1), timeout=600)
            else:
                get(learner.publish_from.remote(newest + 1), timeout=600)
        except Exception:  # noqa: BLE001 - it will not come back: the run stops with the resume line
            log.exception("the learner could not be started again")
            return False
        self.c.restarts["learner"] = used + 1
        self._issue("learner", 0)
        return True

    def _learner_death(self, err: BaseException) -> str:
        used, most = self.c.restarts.get("learner", 0), self.cfg.learner.max_restarts
        tail = (f"; it was started again {used} times (learner.max_restarts={most})" if most else "")
        return f"the learner's process died ({_death(err)}){tail}"

    def _reissue(self, kind: str, i: int) -> None:
        if self.stop_reason is not None:
            return
        schedule = self.roles[kind].schedule
        if schedule == PACED and not self._reanalyze_due():
            self.waiting.add((kind, i))
            return
        if schedule == PERIODIC:
            self.idle.add((kind, i))
            return
        self._issue(kind, i)

    # -- services ------------------------------------------------------------------------
    def _revive_services(self) -> None:
        """Restart the private redis-server if it died (same port and AOF); give a limiter Ray
        restarted its size back; both counted."""
        try:
            if self.topo.replay.revive_server():
                self.c.restarts["redis"] = self.c.restarts.get("redis", 0) + 1
                log.warning("the private redis-server died; restarted at %s from its AOF", self.topo.replay.server_url)
            if self.topo.replay.resync_limiter():
                self.c.restarts["limiter"] = self.c.restarts.get("limiter", 0) + 1
                log.warning("the replay's rate limiter was restarted; its size taken from the shards again")
        except Exception as err:  # noqa: BLE001 - it will not come back: the outage clock decides
            self._replay_outage(err)

    def _replay_outage(self, err: BaseException | str) -> bool:
        """Note that a role could not reach the replay store; True (and a stop reason) once it has
        been unreachable for REPLAY_OUTAGE_SECONDS."""
        now = time.monotonic()
        if self.outage_since is None:
            self.outage_since = now
            return False
        if now - self.outage_since < REPLAY_OUTAGE_SECONDS:
            return False
        where = self.topo.replay.server_url or "the replay store"
        why = err if isinstance(err, str) else _root_cause(err)
        self.stop_reason = ("error", f"replay at {where} has been unreachable for {REPLAY_OUTAGE_SECONDS:.0f}s "
                            f"({why})")
        return True

    # -- the loop ------------------------------------------------------------------------
    def elapsed(self) -> float:
        return self.elapsed0 + time.monotonic() - self.t_start

    def _budget_done(self) -> bool:
        r = self.cfg.run
        return bool((r.max_env_steps and self.c.env_steps >= r.max_env_steps)
                    or (r.max_updates and self.c.updates >= r.max_updates)
                    or (r.max_minutes and self.elapsed() >= r.max_minutes * 60))

    def _due_periodic(self, now: float) -> bool:
        """An evaluation is due: `eval.every_seconds` since the last, or `eval.every_env_steps`
        more env steps."""
        e = self.cfg.eval
        return bool((e.every_seconds > 0 and now - self.last_eval >= e.every_seconds)
                    or (e.every_env_steps > 0 and self.c.env_steps - self.last_eval_steps >= e.every_env_steps))

    def run(self) -> RunResult:
        self.waiting: set[tuple[str, int]] = set()  # paced calls not yet due
        self.idle: set[tuple[str, int]] = set()  # periodic actors between calls
        self.learner_sample_wait = 0.0
        for role in self.roles.values():  # the table's order: the learner before the collectors
            for i in range(len(self.topo.actors.get(role.name, []))):
                if role.schedule == LOOP:
                    self._issue(role.name, i)
                elif role.schedule == PACED:
                    self.waiting.add((role.name, i))
                elif role.schedule == PERIODIC:
                    self.idle.add((role.name, i))
        try:
            while self.stop_reason is None:
                ready, _ = wait(list(self.inflight), num_returns=1, timeout=0.2)
                for ref in ready:
                    kind, i = self.inflight.pop(ref)
                    try:
                        res = get(ref)
                    except Exception as err:  # noqa: BLE001 - classified below
                        log.error("%s %d: a call failed:\n%s", kind, i, err)  # the remote traceback, for the log
                        if self.roles[kind].fatal:
                            if kind == "learner" and _died(err) and not _failed_to_start(err):
                                if self._restart_learner(err):
                                    continue
                                self.stop_reason = ("learner_failed", self._learner_death(err))
                                break
                            self.stop_reason = (f"{kind}_failed", f"the {kind} failed: {_one_line(err)}")
                            break
                        if _failed_to_start(err):  # a restart would fail the same way
                            self.stop_reason = ("error", f"{kind} {i} could not start: {_root_cause(err)}")
                            break
                        if transient(err):  # the replay store is away: ask again once it may be back
                            if self._replay_outage(err):
                                break
                            self.retry_at[(kind, i)] = time.monotonic() + REPLAY_RETRY_SECONDS
                            continue
                        if _died(err):  # Ray restarts it; ask again shortly (counted when it answers)
                            if self._restarts_used_up(kind, i):
                                self.stop_reason = ("error", f"{kind} {i} died and its restarts are used up "
                                                    f"(actors.max_restarts={self.cfg.actors.max_restarts}): "
                                                    f"{_one_line(err)}")
                                break
                            self.retry_at[(kind, i)] = time.monotonic() + RETRY_SECONDS
                            continue
                        if kind == "collector":
                            self.stop_reason = ("error", f"collector {i} failed: {_one_line(err)}")
                            break
                        raise
                    if res.get("status") == "replay_down":
                        self._note_process(kind, i, res)
                        if self._replay_outage(res["message"]):
                            break
                        self.retry_at[(kind, i)] = time.monotonic() + REPLAY_RETRY_SECONDS
                        continue
                    self._handle(kind, i, res)
                    self._reissue(kind, i)
                for kind, i in sorted(self.waiting):
                    if self._reanalyze_due():
                        self.waiting.discard((kind, i))
                        self._issue(kind, i)
                now = time.monotonic()
                if now - self.last_service_check >= SERVICE_CHECK_SECONDS:
                    self.last_service_check = now
                    self._revive_services()
                for (kind, i), at in list(self.retry_at.items()):
                    if now >= at:
                        del self.retry_at[(kind, i)]
                        self._reissue(kind, i)
                if self.idle and self._due_periodic(now):
                    self.last_eval, self.last_eval_steps = now, self.c.env_steps
                    for kind, i in sorted(self.idle):
                        self._issue(kind, i)
                    self.idle.clear()
                if now - self.last_tick >= self.cfg.run.log_every_seconds:
                    self.tick()
                if self._budget_done() and self.stop_reason is None:
                    self.stop_reason = ("done", "budget reached")
                target = self.cfg.run.stop_at_eval_return
                if target is not None and self.eval_return is not None and self.eval_return >= target \
                        and self.stop_reason is None:
                    self.stop_reason = ("done", f"eval return {self.eval_return:.4g} reached {target:g}")
        except KeyboardInterrupt:
            self.stop_reason = ("interrupted", "interrupted by the user")
        status, message = self.stop_reason
        try:
            self._drain()
            self.tick(force_plot=True)
        except KeyboardInterrupt:  # a second Ctrl-C: skip the drain, still checkpoint
            status, message = "interrupted", "interrupted by the user"
        if status != "learner_failed":
            try:
                self.checkpoint()
            except KeyboardInterrupt:  # the write is atomic: the previous checkpoint stays
                status, message = "interrupted", "interrupted by the user during the final checkpoint"
        return RunResult(status, message, self.c)

    def _drain(self, timeout: float = 30.0) -> None:
        """Let in-flight calls finish so their data lands (bounded), then forget them."""
        refs = [r for r, (k, _) in self.inflight.items() if self.roles[k].drain]
        deadline = time.monotonic() + timeout
        while refs and time.monotonic() < deadline:
            ready, refs = wait(refs, num_returns=1, timeout=max(deadline - time.monotonic(), 0.01))
            for ref in ready:
                kind, i = self.inflight.pop(ref)
                try:
                    self._handle(kind, i, get(ref))
                except Exception:  # noqa: BLE001 - a dying actor's last call is lost
                    pass
        self.inflight.clear()

    # -- checkpoints, logs, metrics ---------------------------------------------------------
    def checkpoint(self) -> Path | None:
        """Write a checkpoint; None (and `checkpoint_error` set, the traceback in the log) when it
        could not be written. A checkpoint is complete or absent: the last good one stays."""
        self.last_ckpt = time.monotonic()
        self.c.elapsed_seconds = self.elapsed()
        try:
            state = get(self.topo.learner.state.remote(), timeout=120)
            version, weights = get(self.topo.learner.weights.remote(), timeout=120)
            if self.final_weights is not None:
                version, weights = self.final_weights  # what the evaluator judged, not what came after
        except Exception:  # noqa: BLE001 - the learner is gone: nothing newer to save
            return None
        replay = self.topo.replay if self.cfg.checkpoint.replay else None
        for last_try in (False, True):
            try:
                path = save_checkpoint(self.topo.run_dir, state, weights, version, self.c.as_dict(), replay,
                                       self.cfg.checkpoint.keep)
            except Exception as err:  # noqa: BLE001 - reported in one line by the caller
                log.exception("checkpoint failed")
                self.checkpoint_error = _root_cause(err)
                if last_try or not transient(err):
                    return None
                time.sleep(REPLAY_RETRY_SECONDS)  # replay's server may be restarting: once more
                self._revive_services()
                continue
            self.last_checkpoint, self.checkpoint_error = path, None
            return path
        return None  # unreachable: the last try returns

    def _log(self, record: dict) -> None:
        if self.log_path is None:
            return
        from wmdist.telemetry.curves import write_jsonl

        full = {"time": round(self.elapsed(), 3), "env_steps": self.c.env_steps, "updates": self.c.updates, **record}
        write_jsonl(self.log_path, full)
        if self.on_record is not None:
            self.on_record(full)

    def snapshot(self, replay_stats: dict | None = None) -> dict:
        c = self.c
        versions = [v for v in self.collector_versions.values() if v >= 0]
        snap = {
            "elapsed_seconds": self.elapsed(),
            "env_steps": c.env_steps, "env_steps_per_second": self.rates["env_steps"],
            "episodes": c.episodes, "updates": c.updates, "updates_per_second": self.rates["updates"],
            "version": c.version, "version_gap": (c.version - min(versions)) if versions else 0,
            "train_return": float(np.mean(self.train_returns)) if self.train_returns else None,
            "train_length": float(np.mean(self.train_lengths)) if self.train_lengths else None,
            "eval_return": self.eval_return, "eval_length": self.eval_length, "eval_episodes": c.eval_episodes,
            "losses": dict(self.losses), "nan_skips": c.nan_skips, "reanalyzed": c.reanalyzed,
            "sampled_sequences": c.sampled_sequences,
            "restarts": dict(c.restarts), "busy": dict(c.busy), "replay": replay_stats or {},
            "limiter_blocked_segments": self.limiter_blocked,
        }
        return snap

    def _rate_counts(self) -> dict[str, float]:
        return {"env_steps": float(self.c.env_steps), "updates": float(self.c.updates)}

    def _work_counts(self) -> dict:
        """For the train line: what reanalyzers did against what the learner sampled (their paced share),
        and each role's busy seconds so far (where the machine's time went)."""
        c = self.c
        out = {f"busy/{role}": round(sec, 1) for role, sec in c.busy.items() if sec > 0}
        if self.cfg.reanalyze.num:
            out.update(reanalyzed=c.reanalyzed, sampled_sequences=c.sampled_sequences)
        return out

    def tick(self, force_plot: bool = False) -> dict:
        now = time.monotonic()
        self.rates = self._rates.update(now, self._rate_counts())
        self.last_tick = now
        try:
            replay_stats = self.topo.replay.stats()
        except Exception:  # noqa: BLE001 - a restarting shard: show the last figures
            replay_stats = self.last_snapshot.get("replay", {})
        snap = self.snapshot(replay_stats)
        self.last_snapshot = snap
        self._log({"kind": "train", "train_return": snap["train_return"], "version": snap["version"],
                   "env_steps_per_second": round(snap["env_steps_per_second"], 2),
                   "updates_per_second": round(snap["updates_per_second"], 3),
                   **{f"loss/{k}": v for k, v in snap["losses"].items()}, **self._work_counts()})
        if self.on_tick is not None:
            self.on_tick(snap)
        if self.plot is not None and (force_plot or now - self.last_plot >= self.cfg.run.plot_every_seconds):
            self.last_plot = now
            try:
                self.plot()
            except Exception:  # noqa: BLE001 - a plot must never stop training
                pass
        return snap
