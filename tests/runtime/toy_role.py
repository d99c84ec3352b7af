"""A toy algorithm that adds a role of its own (a pool of "toy" actors the driver keeps
busy), to show that a new role is one table entry and no runtime edit.
Plugged in as `algo.name: tests.runtime.toy_role:ToyAlgo`."""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

from tests.runtime.fake_algo import FakeAlgo, FakeConfig
from wmdist.config.fields import param
from wmdist.runtime.table import LOOP, Role, RoleResources, answer_busy


@dataclass
class ToyConfig(FakeConfig):
    toy_num: int = param(2, "toy actors", ge=0)
    toy_cpus: float = param(0.05, "Ray CPUs per toy actor", gt=0)


class ToyActor:
    """Works ~20 ms per call and says who answered (the driver counts restarts by it)."""

    def __init__(self, index: int) -> None:
        self.index, self.calls = index, 0

    def tick(self) -> dict:
        t0 = time.monotonic()
        time.sleep(0.02)
        self.calls += 1
        return {"busy_seconds": time.monotonic() - t0, "pid": os.getpid(), "restarted": False, "calls": self.calls}

    def pid(self) -> int:
        return os.getpid()


def _toy_answer(d, i: int, res: dict) -> None:
    answer_busy(d, "toy", res)
    d.toy_calls = getattr(d, "toy_calls", 0) + 1


class ToyAlgo(FakeAlgo):
    name = "toy"
    Config = ToyConfig

    @classmethod
    def extra_roles(cls, run_config) -> list:
        return [Role("toy", lambda: ToyActor, lambda cfg: cfg.algo, lambda cfg: cfg.algo.toy_num,
                     lambda sec: RoleResources(sec.toy_cpus), args=lambda ctx, i, res: (i,),
                     schedule=LOOP, call=lambda a, d: a.tick.remote(), handle=_toy_answer)]
