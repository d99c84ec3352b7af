"""A small fake algorithm that isolates the runtime under test: a linear policy whose
greedy action follows its weights, a learner that takes real (tiny) gradient steps, and a
reanalyzer that rewrites one stored field. Plugged in as `algo.name: tests.runtime.fake_algo:FakeAlgo`."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from wmdist.algos.base import REANALYZE, Algorithm, FieldSpec, Learner, Policy, Reanalyzer, UpdateResult
from wmdist.config.fields import param
from wmdist.nets.optim import GuardedStep, OptimConfig


@dataclass
class FakeConfig:
    lr: float = param(0.05, "learning rate of the linear model", gt=0)
    nan_every: int = param(0, "make every update's loss NaN from update N on (0 = never)", ge=0)
    update_sleep: float = param(0.0, "seconds each update sleeps (a slow learner)", ge=0)
    act_sleep: float = param(0.0, "seconds each act call sleeps (a slow policy)", ge=0)
    crash_at: int = param(0, "raise an exception in update N (0 = never): a learner failure", ge=0)
    policy_fails: bool = param(False, "make_policy raises: collectors fail in their constructor")


def _obs_dim(spec) -> int:
    return int(np.prod(spec.obs_shape))


class FakePolicy(Policy):
    def __init__(self, spec, seed: int) -> None:
        self.spec, self.cfg_sleep = spec, 0.0
        self.w = np.zeros((_obs_dim(spec), spec.num_actions), np.float32)
        self.version = -1
        self.rng = np.random.default_rng(seed)

    def set_weights(self, weights, version) -> None:
        self.w = np.asarray(weights["w"], np.float32)
        self.version = version

    def act(self, obs, first, legal, to_play, explore):
        if self.cfg_sleep:
            time.sleep(self.cfg_sleep)
        logits = obs.reshape(len(obs), -1).astype(np.float32) @ self.w  # [E, A]
        actions = logits.argmax(-1)
        if explore:
            rand = self.rng.random(len(obs)) < 0.3
            actions = np.where(rand, self.rng.integers(0, self.spec.num_actions, len(obs)), actions)
        return actions.astype(np.int64), {"version_seen": np.full(len(obs), self.version, np.int32)}


class FakeLearner(Learner):
    def __init__(self, spec, cfg: FakeConfig, seed: int) -> None:
        torch.manual_seed(seed)
        self.cfg = cfg
        self.w = torch.nn.Parameter(torch.randn(_obs_dim(spec), spec.num_actions) * 0.1)
        self.step = GuardedStep([self.w], OptimConfig(kind="sgd", lr=cfg.lr, momentum=0.9))
        self.updates = 0

    def update(self, batch) -> UpdateResult:
        if self.cfg.update_sleep:
            time.sleep(self.cfg.update_sleep)
        obs = torch.as_tensor(batch["obs"], dtype=torch.float32)  # [B, T, D]
        mask = torch.as_tensor(batch["mask"], dtype=torch.float32)  # [B, T]
        target = torch.as_tensor(batch["reward"], dtype=torch.float32)  # [B, T]
        pred = (obs @ self.w).mean(-1)  # [B, T]
        per_seq = ((pred - target) ** 2 * mask).sum(1) / mask.sum(1).clamp(min=1)  # [B]
        loss = (per_seq * torch.as_tensor(batch["is_weight"])).mean()
        if self.cfg.crash_at and self.updates + 1 >= self.cfg.crash_at:
            raise RuntimeError("simulated learner crash")
        if self.cfg.nan_every and self.updates + 1 >= self.cfg.nan_every:
            loss = loss * float("nan")
        self.step(loss)
        self.updates += 1
        return UpdateResult({"loss": float(loss)}, per_seq.detach().numpy() + 1e-3)

    def get_weights(self):
        return {"w": self.w.detach().numpy().copy()}

    def state_dict(self):
        return {"w": self.w.detach().clone(), "opt": self.step.state_dict(), "updates": self.updates}

    def load_state_dict(self, state) -> None:
        with torch.no_grad():
            self.w.copy_(state["w"])
        self.step.load_state_dict(state["opt"])
        self.updates = int(state["updates"])


class FakeReanalyzer(Reanalyzer):
    def __init__(self) -> None:
        self.version = -1

    def set_weights(self, weights, version) -> None:
        self.version = version

    def reanalyze(self, batch):
        return {"version_seen": np.full(batch["mask"].shape, 1000 + self.version, np.int32)}


class FakeAlgo(Algorithm):
    name = "fake"
    Config = FakeConfig
    capabilities = frozenset({REANALYZE})

    def validate(self) -> None:
        if not self.spec.discrete:
            raise ValueError("the fake algorithm needs discrete actions")

    def extra_fields(self):
        return {"version_seen": FieldSpec((), "int32")}

    def make_policy(self, device="cpu"):
        if self.config.policy_fails:
            raise ValueError("simulated policy construction failure")
        p = FakePolicy(self.spec, self.seed)
        p.cfg_sleep = self.config.act_sleep
        return p

    def make_learner(self, device="cpu"):
        return FakeLearner(self.spec, self.config, self.seed)

    def make_reanalyzer(self, device="cpu"):
        return FakeReanalyzer()
