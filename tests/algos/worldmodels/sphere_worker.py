"""A stand-in evaluation actor with the pool's interface (`load_model`, `evaluate`) whose
fitness is a shifted sphere, so the search's optimum is known. It can be told to kill its
own process in the middle of a call, once (a marker file remembers it died)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

SHIFT = np.array([1.5, -2.0, 0.5, 3.0, -1.0])  # the optimum


class SphereWorker:
    def __init__(self, index: int, die_marker: str = "") -> None:
        self.index, self.die_marker, self.model_id, self.calls = index, die_marker, -1, 0

    def load_model(self, model_id: int, weights: dict) -> bool:
        assert float(weights["scale"]) == 1.0
        self.model_id = model_id
        return True

    def evaluate(self, model_id: int, params: np.ndarray, seeds: np.ndarray, mode: str) -> dict:
        if model_id != self.model_id:
            return {"missing_model": True}
        self.calls += 1
        if self.die_marker and self.calls == 3 and not Path(self.die_marker).exists():
            Path(self.die_marker).write_text(str(os.getpid()))
            os._exit(1)  # dies mid-call: this share's candidates must be scored elsewhere
        fitness = -np.sum((np.asarray(params, np.float64) - SHIFT) ** 2, axis=1)  # [n]
        return {"fitness": fitness.tolist(), "pid": os.getpid()}

    def pid(self) -> int:
        return os.getpid()
