"""Live console progress of a training run, fed with the driver's snapshot dicts.

On a terminal one line is redrawn in place at every update; elsewhere (CI, a log file)
a plain line is printed at most every `plain_every_s` seconds, plus a final one on close.
Missing keys (a partial snapshot early in a run) show as `-`.
"""
from __future__ import annotations

import math
import re
import shutil
import sys
import time
from typing import Any, Callable, Mapping, TextIO

from wmdist.telemetry.metrics import snapshot_key


def _num(x: float | None) -> str:
    """Compact number: 950, 12.3k, 4.56M; `-` when unknown."""
    if x is None or not math.isfinite(x):
        return "-"
    a = abs(x)
    for div, suffix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if a >= div:
            return f"{x / div:.3g}{suffix}"
    return f"{x:.4g}" if a < 100 else f"{x:.0f}"


def _dur(seconds: float | None) -> str:
    """`1h02m`, `3m07s`, `42s`; `-` when unknown."""
    if seconds is None or not math.isfinite(seconds) or seconds < 0:
        return "-"
    s = int(round(seconds))
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    if s >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s}s"


class _View:
    """Reads a snapshot in either spelling: the driver's dict (`env_steps`, `losses`,
    `replay: {shard0_size_steps: ..}`) or `MetricsHub.snapshot()` (`wmdist_...` keys)."""

    def __init__(self, snap: Mapping[str, Any]) -> None:
        self.s = snap

    def num(self, *keys: str) -> float | None:
        for k in keys:
            v = self.s.get(k)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                return float(v)
        return None

    def headline(self) -> tuple[str, float | None]:
        """(label, value) of the learner's figure for the line. A learner whose stage has no loss
        names its figure `headline_<label>` (World Models' search: `headline_fitness`); else the
        `total` loss, else the first loss by name."""
        losses = self.s.get("losses")
        if isinstance(losses, Mapping):
            named = {str(k): v for k, v in losses.items() if isinstance(v, (int, float))}
        else:
            prefix = "wmdist_learner_loss{name="
            named = {k[len(prefix) : -1]: v for k, v in self.s.items() if k.startswith(prefix)}
        heads = sorted(k for k in named if k.startswith(_HEADLINE))
        if heads:
            return heads[0][len(_HEADLINE):], float(named[heads[0]])
        if not named:
            return "loss", None
        return "loss", float(named["total"] if "total" in named else named[sorted(named)[0]])

    def replay_steps(self) -> float | None:
        """Steps held by all replay shards together."""
        replay = self.s.get("replay")
        if isinstance(replay, Mapping):
            sizes = [v for k, v in replay.items() if _SHARD_SIZE.match(str(k)) and isinstance(v, (int, float))]
        else:
            sizes = [v for k, v in self.s.items() if k.startswith("wmdist_replay_size_steps{")]
        return float(sum(sizes)) if sizes else None


    def troubles(self) -> str:
        """Drops and restarts that are not zero, e.g. `drops corrupt 3 | restarts collector 1`
        ('' when there are none). FIFO evictions are the buffer working as meant: not shown."""
        drops: dict[str, float] = {}
        restarts: dict[str, float] = {}
        replay = self.s.get("replay")
        if isinstance(replay, Mapping):
            for k, v in replay.items():
                m = _SUMMED_DROP.match(str(k))
                if m and isinstance(v, (int, float)):
                    drops[m.group(1)] = float(v)
            for role, v in (self.s.get("restarts") or {}).items():
                if isinstance(v, (int, float)):
                    restarts[str(role)] = float(v)
        else:
            for k, v in self.s.items():
                m = _HUB_DROP.match(k)
                if m:
                    drops[m.group(1)] = drops.get(m.group(1), 0.0) + float(v)
                m = _HUB_RESTART.match(k)
                if m:
                    restarts[m.group(1)] = float(v)
        parts = []
        shown = [f"{r} {_num(n)}" for r, n in sorted(drops.items()) if n and r != "evicted"]
        if shown:
            parts.append("drops " + ", ".join(shown))
        shown = [f"{r} {_num(n)}" for r, n in sorted(restarts.items()) if n]
        if shown:
            parts.append("restarts " + ", ".join(shown))
        return " | ".join(parts)


_HEADLINE = "headline_"
_SHARD_SIZE = re.compile(r"^shard\d+_size_steps$")
_SUMMED_DROP = re.compile(r"^drops_(\w+)$")  # the replay stats' sums over shards
_HUB_DROP = re.compile(r"^wmdist_replay_drops_total\{shard=\d+,reason=(\w+)\}$")
_HUB_RESTART = re.compile(r"^wmdist_actor_restarts_total\{role=(\w+)\}$")


class Progress:
    """Console view of a run that stops at `total_env_steps` or `total_minutes`, whichever first.

    A limit of 0 means none (as `run.max_env_steps = 0` in the config).
    """

    def __init__(
        self,
        total_env_steps: int,
        total_minutes: float,
        stream: TextIO = sys.stdout,
        *,
        plain_every_s: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if total_env_steps < 0:
            raise ValueError(f"total_env_steps must be >= 0 (0 = no limit), got {total_env_steps}")
        if not total_minutes >= 0:
            raise ValueError(f"total_minutes must be >= 0 (0 = no limit), got {total_minutes}")
        self.total_env_steps = int(total_env_steps)
        self.total_s = float(total_minutes) * 60.0
        self.stream = stream
        self.plain_every_s = plain_every_s
        self._clock = clock
        self._t0 = clock()
        self._tty = bool(getattr(stream, "isatty", lambda: False)())
        self._last_print: float | None = None
        self._last_line = ""
        self._last_shown = True  # plain mode: was the latest line printed?
        self._width = 0  # of the line drawn in place (TTY), to blank leftovers
        self._closed = False

    def format(self, snap: Mapping[str, Any]) -> str:
        """One status line for a snapshot (public so the line can be logged or tested)."""
        v = _View(snap)
        elapsed = v.num("elapsed_seconds")
        if elapsed is None:
            elapsed = self._clock() - self._t0
        steps = v.num("env_steps", "wmdist_env_steps_total")
        sps = v.num("env_steps_per_second", "wmdist_env_steps_per_second")
        # ETA: the run ends at whichever limit comes first (a 0 limit is no limit).
        eta = math.inf
        if self.total_s:
            eta = max(self.total_s - elapsed, 0.0)
        if self.total_env_steps:
            frac = steps / self.total_env_steps if steps is not None else None
            pct = f"{100 * min(frac, 1.0):.0f}%" if frac is not None else "-"
            steps_text = f"steps {_num(steps)}/{_num(self.total_env_steps)} ({pct})"
            if steps is not None and sps:
                eta = min(eta, max((self.total_env_steps - steps) / sps, 0.0))
        else:
            steps_text = f"steps {_num(steps)}"
        label, value = v.headline()
        parts = [
            steps_text,
            f"{_num(sps)}/s",
            f"upd {_num(v.num('updates', 'wmdist_learner_updates_total'))}",
            f"{_num(v.num('updates_per_second', 'wmdist_learner_updates_per_second'))}/s",
            f"ret train {_num(v.num('train_return', snapshot_key('wmdist_episode_return', role='train')))}",
            f"eval {_num(v.num('eval_return', snapshot_key('wmdist_episode_return', role='eval')))}",
            f"{label} {_num(value)}",
            f"replay {_num(v.replay_steps())}",
            f"w v{_num(v.num('version', 'wmdist_weights_version'))}"
            f" gap {_num(v.num('version_gap', 'wmdist_weights_version_gap'))}",
            f"{_dur(elapsed)} eta {_dur(eta)}",
        ]
        troubles = v.troubles()
        if troubles:
            parts.append(troubles)
        return " | ".join(parts)

    def update(self, snapshot: Mapping[str, Any]) -> None:
        """Show the latest snapshot (redraw on a TTY; throttled plain lines otherwise)."""
        if self._closed:
            return
        line = self.format(snapshot)
        self._last_line = line
        self._last_shown = False
        now = self._clock()
        if self._tty:
            # Fit the terminal: a wrapped line could not be redrawn in place.
            line = line[: max(shutil.get_terminal_size().columns - 1, 20)]
            pad = max(self._width - len(line), 0)
            self.stream.write("\r" + line + " " * pad)
            self._width = len(line)
            self.stream.flush()
        elif self._last_print is None or now - self._last_print >= self.plain_every_s:
            self.stream.write(line + "\n")
            self.stream.flush()
            self._last_print = now
            self._last_shown = True

    def close(self) -> None:
        """End the view: finish the TTY line, or print the last state if it was not shown."""
        if self._closed:
            return
        self._closed = True
        if self._tty:
            if self._width:
                self.stream.write("\n")
        elif not self._last_shown:
            self.stream.write(self._last_line + "\n")
        self.stream.flush()
