"""CMA-ES over a flat parameter vector (Hansen's `cma` package): ask / evaluate / tell.

Fitness is maximised (returns, steps survived); `cma` minimises, so it is told -fitness.
The search state is saved as plain arrays (mean, step size, covariance, evolution paths,
counters) and rebuilt into a fresh `cma.CMAEvolutionStrategy`, so a checkpoint never
unpickles an object.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

MIN_POPSIZE = 2  # cma's weighted recombination needs at least two parents' weights


def covariance_bytes(dim: int) -> int:
    """What full-covariance CMA-ES holds at least: the matrix C and its eigenvectors B, float64 [P, P] each."""
    return 2 * dim * dim * 8


class CMAES:
    def __init__(self, dim: int, popsize: int, sigma0: float, seed: int = 0, x0: np.ndarray | None = None) -> None:
        if popsize < MIN_POPSIZE:
            raise ValueError(f"CMA-ES population must be >= {MIN_POPSIZE}, got {popsize}")
        self.dim, self.popsize, self.sigma0, self.seed = dim, popsize, sigma0, seed
        self.es = self._fresh(np.zeros(dim) if x0 is None else np.asarray(x0, np.float64), sigma0)
        self.best_x = np.array(self.es.mean, np.float64)  # [P]
        self.best_f = -np.inf
        self.generation = 0

    def _fresh(self, x0: np.ndarray, sigma: float):
        import cma

        # CSA step-size control always (cma picks TPA for some sizes): its one path `ps` is the state saved
        opts = {"popsize": self.popsize, "seed": self.seed + 1, "verbose": -9, "CMA_diagonal": False,
                "AdaptSigma": cma.sigma_adaptation.CMAAdaptSigmaCSA,
                "tolfun": 0, "tolx": 0, "tolfunhist": 0, "tolstagnation": int(1e9), "tolflatfitness": int(1e9)}
        return cma.CMAEvolutionStrategy(x0, sigma, opts)

    @property
    def mean(self) -> np.ndarray:
        return np.asarray(self.es.mean, np.float64)

    @property
    def sigma(self) -> float:
        return float(self.es.sigma)

    def ask(self) -> np.ndarray:
        """The generation's candidates [popsize, P]."""
        return np.asarray(self.es.ask(), np.float64)

    def tell(self, candidates: np.ndarray, fitness: np.ndarray) -> None:
        """candidates [N, P] with their fitness [N] (higher is better)."""
        fitness = np.asarray(fitness, np.float64)
        self.es.tell(list(candidates), list(-fitness))
        i = int(np.argmax(fitness))
        if fitness[i] > self.best_f:
            self.best_f, self.best_x = float(fitness[i]), np.array(candidates[i], np.float64)
        self.generation += 1

    def step(self, evaluate: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """One generation: ask, `evaluate` candidates [N, P] -> fitness [N], tell; returns the fitness."""
        x = self.ask()
        f = np.asarray(evaluate(x), np.float64)
        self.tell(x, f)
        return f

    # -- state as arrays ---------------------------------------------------------------------
    def state(self) -> dict[str, np.ndarray]:
        es = self.es
        ps = es.adapt_sigma.ps if getattr(es.adapt_sigma, "ps", None) is not None else np.zeros(self.dim)  # None before a tell
        return {
            "mean": self.mean, "sigma": np.array(self.sigma), "C": np.asarray(es.sm.C, np.float64),
            "pc": np.asarray(es.pc, np.float64), "ps": np.asarray(ps, np.float64),
            "countiter": np.array(es.countiter), "countevals": np.array(es.countevals),
            "best_x": self.best_x, "best_f": np.array(self.best_f), "generation": np.array(self.generation),
            "popsize": np.array(self.popsize),
        }

    def load(self, state: dict) -> None:
        """Rebuild the search from `state()`'s arrays (scalars may come back as [1] arrays)."""
        s = {k: np.asarray(v) for k, v in state.items()}
        for k in ("sigma", "countiter", "countevals", "best_f", "generation", "popsize"):
            s[k] = s[k].reshape(-1)[0]
        if s["mean"].shape != (self.dim,) or int(s["popsize"]) != self.popsize:
            raise ValueError(f"CMA-ES state is for {s['mean'].shape[0]} parameters and population "
                             f"{int(s['popsize'])}, this search has {self.dim} and {self.popsize}")
        es = self._fresh(s["mean"].astype(np.float64), float(s["sigma"]))
        es.sm.C = s["C"].astype(np.float64).copy()
        es.sm._decompose_C()  # B, D (the sampling transform) from C
        es.pc = s["pc"].astype(np.float64).copy()
        es.adapt_sigma.ps = s["ps"].astype(np.float64).copy()
        es.countiter, es.countevals = int(s["countiter"]), int(s["countevals"])
        from cma.utilities import utils

        es.timer = utils.ElapsedWCTime()  # `ask` after iteration 0 expects the timer the first ask made
        es.mean_old = np.array(es.mean)  # and `tell` the previous mean
        es.sm.count_tell = es.sm.last_update = int(s["countiter"])
        self.es = es
        self.best_x, self.best_f = s["best_x"].astype(np.float64), float(s["best_f"])
        self.generation = int(s["generation"])
