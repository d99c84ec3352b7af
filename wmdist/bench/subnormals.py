"""Subnormal floats in a learner's update: time with and without flushing them to zero.

Weight decay pulls unused weights toward zero, and a trained net's weights, activations and
gradients come to hold subnormal floats (|x| < 1.18e-38 in float32). x86 cores compute on
them through microcode assists, many times slower than normal floats. Every role process
therefore flushes them to zero (`wmdist.runtime.roles.setup.set_threads`).

Cases, on the connect-four preset's MuZero conv net (batch 128, one torch thread, the
preset's one-step unroll, forward + backward): the freshly initialised net, and the same net
with a share of every weight tensor (`planted`, 0.1%; a connect-four checkpoint after 60
minutes held 1.5%) set to +-1e-39. Each is timed with flushing off and on, interleaved in
one process, `rounds` times; `slowdown` = planted / fresh time at the same setting, best of
the rounds. A trained checkpoint can be timed instead with `--weights PATH/weights.npz`.

    wmdist bench subnormals --json
    python -m wmdist.bench.subnormals --weights RUN/checkpoints/ckpt-.../weights.npz
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Iterator

import numpy as np

PRESET = Path(__file__).parents[2] / "configs" / "muzero_connect4.yaml"
TINY = 1e-39  # subnormal in float32


def _nets(weights: str | None, planted: float):
    import torch

    from wmdist.algos.muzero.build import build_net, load_numpy_weights
    from wmdist.config.loader import load_config
    from wmdist.envs.factory import env_spec

    cfg = load_config(str(PRESET), [])
    spec = env_spec(cfg.env)
    torch.manual_seed(0)
    fresh = build_net(spec, cfg.algo).train()
    other = build_net(spec, cfg.algo).train()
    other.load_state_dict(fresh.state_dict())
    if weights:
        load_numpy_weights(other, dict(np.load(weights)))
    else:
        gen = torch.Generator().manual_seed(1)
        with torch.no_grad():
            for p in other.parameters():
                if p.dim() > 1:  # weights, not biases or norms
                    hit = torch.rand(p.shape, generator=gen) < planted
                    p[hit] = TINY * torch.sign(torch.randn(int(hit.sum()), generator=gen))
    return fresh, other, spec


def _subnormal_share(net) -> float:
    vals = [p.detach().abs().flatten() for p in net.parameters()]
    allv = np.concatenate([v.numpy() for v in vals])
    return float(((allv > 0) & (allv < np.finfo(np.float32).tiny)).mean())


def run(quick: bool = False, weights: str | None = None, planted: float = 0.001) -> Iterator[dict]:
    import torch

    torch.set_num_threads(1)
    # planting and counting need subnormals to exist: flushing (DAZ/FTZ, set by any role that ran in
    # this process) would turn 1e-39 into 0, in torch and in numpy alike (the flags are the thread's)
    torch.set_flush_denormal(False)
    fresh, other, spec = _nets(weights, planted)
    gen = torch.Generator().manual_seed(2)
    obs = (torch.rand((128, *spec.obs_shape), generator=gen) < 0.3).to(torch.uint8) * 255  # [B, 6, 7, 3]
    actions = torch.randint(0, spec.num_actions, (128,), generator=gen)

    def update(net) -> None:  # the learner's one-step unroll: h, f, then g and f
        net.zero_grad(set_to_none=True)
        s, logits, value = net.initial_inference(obs)
        _, reward, logits2, value2 = net.recurrent_inference(s, actions)
        (logits.logsumexp(-1).sum() + value.sum() + reward.sum() + logits2.sum() + value2.sum()).backward()

    calls, rounds = (1, 1) if quick else (10, 3)
    best: dict[tuple[str, bool], float] = {}
    for _ in range(rounds):
        for flush in (False, True):
            torch.set_flush_denormal(flush)
            for name, net in (("fresh", fresh), ("subnormal", other)):
                update(net)  # warm
                t = time.perf_counter()
                for _ in range(calls):
                    update(net)
                dt = (time.perf_counter() - t) / calls
                best[name, flush] = min(best.get((name, flush), dt), dt)
    torch.set_flush_denormal(False)
    source = weights or f"planted {planted * 100:g}%"
    for flush in (False, True):
        yield {"case": f"flush={'on' if flush else 'off'}", "weights": source,
               "subnormal_share": round(_subnormal_share(other), 4),
               "fresh_ms": round(best["fresh", flush] * 1e3, 2), "subnormal_ms": round(best["subnormal", flush] * 1e3, 2),
               "slowdown": round(best["subnormal", flush] / best["fresh", flush], 3)}
    yield {"case": "flush gain", "weights": source,
           "ratio": round(best["subnormal", False] / best["subnormal", True], 3)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--weights", default=None, help="a checkpoint's weights.npz instead of planted subnormals")
    p.add_argument("--planted", type=float, default=0.001, help="share of each weight tensor set to +-1e-39")
    p.add_argument("--quick", action="store_true")
    a = p.parse_args(argv)
    for case in run(quick=a.quick, weights=a.weights, planted=a.planted):
        print(json.dumps({"bench": "subnormals", **case}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
