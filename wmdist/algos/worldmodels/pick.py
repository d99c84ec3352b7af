"""Which controller the learner publishes: the candidate that scored best when re-evaluated.

A generation scores each candidate on a few rollouts, and the best of `popsize` noisy means is
biased upwards; with the fitness capped (Take Cover's 2,100 steps) the best-ever candidate of an
early lucky generation can never be replaced (session 28). The authors' training script instead
re-scored the search's mean on many rollouts every few generations and kept the best of those
re-scores; this does the same for the mean and the generation's best candidate.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

SOURCES = ("", "mean", "best")  # as saved: none yet, the search's mean, a generation's best


class ControllerPick:
    def __init__(self, dim: int) -> None:
        self.x = np.zeros(dim, np.float64)  # [P] the published controller
        self.f = -np.inf  # its re-evaluated fitness (mean over the re-evaluation's rollouts; reset when M changes)
        self.source = ""  # "mean" or "best": which candidate it was when picked

    @property
    def has(self) -> bool:
        return self.source != ""

    def offer(self, evaluate: Callable[[np.ndarray], np.ndarray], candidates: Mapping[str, np.ndarray]) -> np.ndarray:
        """Re-score `candidates` (name -> [P]) with `evaluate` ([N, P] -> fitness [N], on the
        re-evaluation's rollouts) and keep the best if it beats the current pick; returns the
        fitness [N]."""
        names = list(candidates)
        x = np.stack([np.asarray(candidates[n], np.float64) for n in names])  # [N, P]
        f = np.asarray(evaluate(x), np.float64)  # [N]
        i = int(np.argmax(f))
        if f[i] > self.f:
            self.x, self.f, self.source = x[i].copy(), float(f[i]), names[i]
        return f

    def state(self) -> dict[str, np.ndarray]:
        return {"x": self.x, "f": np.array(self.f), "source": np.array(float(SOURCES.index(self.source)))}

    def load(self, state: Mapping[str, Any]) -> None:
        s = {k: np.asarray(v) for k, v in state.items()}
        self.x = s["x"].astype(np.float64).reshape(-1)
        self.f = float(s["f"].reshape(-1)[0])
        self.source = SOURCES[int(s["source"].reshape(-1)[0])]
