"""The learner's side of the evaluation pool: spread a generation's candidates over the pool's
actors and gather their fitness, re-evaluating the share of an actor that died.

The pool's actors are the `wm_eval` role (`worker.EvalWorker`), built, placed and restarted by
the runtime like any other role; this client only holds their handles and talks through
`wmdist.runtime.calls` (Ray refs, or the local runner's in-process handles). A call that fails
(its actor died: Ray restarts it) is sent again, to the next actor in turn; an actor that comes
back without the current model (a restarted process) answers `missing_model` and is sent it.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np


class PoolFailed(RuntimeError):
    """A share of candidates failed more often than the pool's retry budget."""


class EvalPool:
    def __init__(self, handles: list[Any], max_retries: int = 8, shares_per_actor: int = 2,
                 timeout: float = 600.0) -> None:
        if not handles:
            raise ValueError("the evaluation pool has no actors")
        self.handles, self.max_retries, self.shares_per_actor = list(handles), max_retries, shares_per_actor
        self.timeout = timeout
        self.retries = 0  # shares sent again after a failed call (a dead actor), over the pool's life
        self.model_loads = 0

    def evaluate(self, params: np.ndarray, seeds: np.ndarray, model_id: int,
                 model: Callable[[], dict] | None = None, mode: str = "dream") -> np.ndarray:
        """Fitness [N] of candidates params [N, P], each scored on the rollouts `seeds` [R].

        `model()` returns the weights the actors need for `model_id` (called only when an actor
        lacks them)."""
        from wmdist.runtime.calls import get, wait

        n = params.shape[0]
        size = max(1, math.ceil(n / (len(self.handles) * self.shares_per_actor)))
        shares = [np.arange(i, min(i + size, n)) for i in range(0, n, size)]
        fitness = np.full(n, np.nan)
        tries = [0] * len(shares)
        turn = 0
        inflight: dict[Any, tuple[int, int]] = {}  # ref -> (share, actor)
        payload: dict | None = None

        def send(s: int, a: int | None = None) -> None:
            nonlocal turn
            if a is None:
                a = turn % len(self.handles)
                turn += 1
            ref = self.handles[a].evaluate.remote(model_id, params[shares[s]].astype(np.float32), seeds, mode)
            inflight[ref] = (s, a)

        for s in range(len(shares)):
            send(s)
        while inflight:
            done, _ = wait(list(inflight), num_returns=1, timeout=self.timeout)
            if not done:
                raise PoolFailed(f"no evaluation answered within {self.timeout:.0f} s")
            ref = done[0]
            s, a = inflight.pop(ref)
            try:
                res = get(ref)
            except Exception as err:  # noqa: BLE001 - the actor died (or crashed): evaluate the share again
                tries[s] += 1
                self.retries += 1
                if tries[s] > self.max_retries:
                    raise PoolFailed(f"candidates {shares[s].tolist()} failed {tries[s]} times; last: "
                                     f"{str(err).splitlines()[0] if str(err) else type(err).__name__}") from None
                send(s)
                continue
            if res.get("missing_model"):
                tries[s] += 1  # bounded: a model that never sticks ends in PoolFailed
                if model is None:
                    raise PoolFailed(f"evaluation actor {a} has no model {model_id} and none was given")
                if payload is None:
                    payload = model()
                try:
                    get(self.handles[a].load_model.remote(model_id, payload), timeout=self.timeout)
                    self.model_loads += 1
                    send(s, a)  # the same actor, now holding the model
                except Exception:  # noqa: BLE001 - died meanwhile: the share goes round again
                    tries[s] += 1
                    self.retries += 1
                    if tries[s] > self.max_retries:
                        raise PoolFailed(f"candidates {shares[s].tolist()} could not be evaluated") from None
                    send(s)
                continue
            fitness[shares[s]] = np.asarray(res["fitness"], np.float64)
        return fitness
