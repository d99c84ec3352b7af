"""Per-phase precision of a learner's update: fp32, bf16, or `auto` (measured at start-up).

The phases are the keys of the modes a learner passes in. Dreamer's update has two phases
that pay differently for bf16: the world model (one observe loop over [B, T], matmul-heavy)
and imagination with the actor-critic (H steps over N starts, with a backward through the
dynamics for continuous actions). `auto` runs the first updates
alternately in fp32 and bf16, times each phase (forward + its backward and optimiser step),
drops the first update in each precision as warm-up, and keeps, per phase, the precision
whose mean time was lower. It never chooses bf16 where the device has no native bf16
matmuls (there it is ~10x slower; timing it would cost minutes).
"""
from __future__ import annotations

import contextlib
import logging
from typing import Any, Callable, ContextManager, Mapping

import torch

PHASES = ("world_model", "actor_critic")  # Dreamer's; PlaNet's update is the world model alone
MODES = ("fp32", "bf16", "auto")

log = logging.getLogger(__name__)


def native_bf16(device: torch.device) -> bool:
    """Whether bf16 matmuls run in hardware here (CPU: oneDNN's AVX-512 BF16 / AMX check)."""
    if device.type == "cuda":
        return bool(torch.cuda.is_bf16_supported())
    if device.type == "cpu":
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    return False


class PhasePrecision:
    """The precision each phase runs in, and, for `auto` phases, the start-up measurement."""

    def __init__(self, modes: Mapping[str, str], device: torch.device, trials: int = 2, bf16_ok: bool | None = None,
                 clock: Callable[[], float] | None = None) -> None:
        import time

        self.phases = tuple(modes)
        for phase in self.phases:
            if modes[phase] not in MODES:
                raise ValueError(f"precision of {phase} must be one of {MODES}, got {modes[phase]!r}")
        self.device, self.trials = device, trials
        self.clock = clock or time.perf_counter
        ok = native_bf16(device) if bf16_ok is None else bf16_ok
        # the fixed choice per phase; an `auto` phase is absent until measured
        self.choice: dict[str, str] = {}
        for phase in self.phases:
            if modes[phase] != "auto":
                self.choice[phase] = modes[phase]
            elif not ok:
                self.choice[phase] = "fp32"
        self.reason = "" if ok else "no native bf16 on this device"
        self.seconds: dict[str, dict[str, list[float]]] = {p: {"fp32": [], "bf16": []} for p in self.phases}
        self._step = 0  # measured updates so far

    @property
    def measuring(self) -> bool:
        return len(self.choice) < len(self.phases)

    def _trial(self) -> str:
        """The precision this trial update runs in: fp32, bf16, fp32, ... (the first of each is warm-up)."""
        return "fp32" if self._step % 2 == 0 else "bf16"

    def mode(self, phase: str) -> str:
        return self.choice.get(phase) or self._trial()

    def autocast(self, phase: str) -> ContextManager:
        if self.mode(phase) == "bf16":
            return torch.autocast(self.device.type, dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def timed(self, phase: str, spent: dict[str, float]) -> ContextManager:
        """Adds the wall time of the block to `spent[phase]` (the clock is read only while measuring)."""
        @contextlib.contextmanager
        def ctx():
            if phase in self.choice:
                yield
                return
            t0 = self.clock()
            try:
                yield
            finally:
                spent[phase] = spent.get(phase, 0.0) + self.clock() - t0
        return ctx()

    def end_update(self, spent: Mapping[str, float]) -> dict[str, float]:
        """Records one update's phase times; returns metrics (the precision each phase used as
        0/1, and on the update that fixes a choice, the mean seconds of each precision)."""
        metrics = {f"bf16_{p}": float(self.mode(p) == "bf16") for p in self.phases}
        if not self.measuring:
            return metrics
        trial = self._trial()
        if self._step >= 2:  # the first update in each precision is warm-up
            for phase, s in spent.items():
                self.seconds[phase][trial].append(s)
        self._step += 1
        if self._step >= 2 * (self.trials + 1):
            for phase in self.phases:
                if phase in self.choice:
                    continue
                t32, t16 = (sum(v) / len(v) for v in (self.seconds[phase]["fp32"], self.seconds[phase]["bf16"]))
                self.choice[phase] = "bf16" if t16 < t32 else "fp32"
                metrics[f"precision_{phase}_fp32_s"] = t32
                metrics[f"precision_{phase}_bf16_s"] = t16
            log.info("learner precision chosen: %s (%s)", self.describe(),
                     ", ".join(f"{k}={v:.3f}s" for k, v in metrics.items() if k.startswith("precision_")))
        return metrics

    def describe(self) -> str:
        chosen = " ".join(f"{p}={self.choice.get(p, 'measuring')}" for p in self.phases)
        return chosen + (f" ({self.reason})" if self.reason else "")

    def state_dict(self) -> dict[str, Any]:
        return {"choice": dict(self.choice)}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """A resumed run keeps the measured choice (phases configured fp32/bf16 keep their setting)."""
        for phase, mode in state.get("choice", {}).items():
            self.choice.setdefault(phase, mode)
