"""Why a Dreamer agent's CartPole-v1 episodes end, and whether its critic sees it coming (issue 24).

    python -m wmdist.bench.cartpole_probe RUN_DIR [--episodes 10] [--explore]

Plays episodes with the run's latest checkpoint (the actor's mode unless --explore) and prints one
JSON line per episode: its length, how it ended (`x`: the cart left the track, |x| > 2.4; `angle`: the
pole fell past 12 degrees; `limit`: 500 steps), the furthest the cart got and the side it drifted to.
A last line gives the critic's mean value over every step, binned by |x|. A critic that cannot tell a
cart resting near the edge from a centred one gives flat bins; the actor then has no reason to
re-centre the cart, and a version that drifts a little further ends its episodes at the edge.
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Iterator

import numpy as np
import torch

from wmdist.config.errors import ConfigError

X_LIMIT = 2.4  # gymnasium CartPole-v1: the episode terminates once |x| exceeds this
X_BINS = (0.0, 0.5, 1.0, 1.5, 2.0, X_LIMIT)  # |x| edges of the value summary


def _critic(algo, policy, ckpt):
    """The checkpoint's critic (weights published to actors carry the actor only)."""
    from wmdist.algos.dreamer.nets import ActorCritic
    from wmdist.nets.dists import twohot_bins, twohot_mean
    from wmdist.runtime import checkpoint as ck

    cfg = policy.cfg
    ac = ActorCritic(cfg, policy.spec, policy.wm.rssm.z_dim)
    ac.load_state_dict(ck.load_learner_state(ckpt)["learner"]["ac"])
    ac.eval()
    if cfg.critic_head == "twohot":
        bins = twohot_bins(cfg.bins, cfg.bin_low, cfg.bin_high)
        return lambda h, z: twohot_mean(ac.critic({"h": h, "z": z})["critic"], bins)
    return lambda h, z: ac.critic({"h": h, "z": z})["critic"].float().squeeze(-1)


def probe(run_dir: str, episodes: int, explore: bool = False, seed: int = 1000) -> Iterator[dict]:
    """One dict per episode, then the value summary (see the module docstring)."""
    from wmdist.runtime.evaluate import load_run
    from wmdist.envs.factory import make_env

    cfg, spec, algo, version, weights, ckpt = load_run(run_dir)
    if cfg.algo_name != "dreamer" or cfg.env.id != "gym:CartPole-v1":
        raise ConfigError(f"{run_dir}: the probe reads Dreamer runs on gym:CartPole-v1, not "
                          f"{cfg.algo_name} on {cfg.env.id}")
    policy = algo.make_policy("cpu")
    policy.set_weights(weights, version)
    value_of = _critic(algo, policy, ckpt)
    env = make_env(cfg.env, seed)
    xs, values = [], []  # every step of every episode: |x| [n] and the critic's value [n]
    for ep in range(episodes):
        obs, first, steps, max_x, end = env.reset(seed + ep), True, 0, 0.0, "limit"
        path = []
        while True:
            action, _ = policy.act(obs[None], np.array([first]), None, None, explore)
            with torch.no_grad():  # the posterior state the action was chosen in (act keeps it)
                values.append(float(value_of(policy.h, policy.z).reshape(-1)[0]))
            xs.append(abs(float(obs[0])))
            path.append(float(obs[0]))
            obs, _, terminated, truncated = env.step(int(np.asarray(action).reshape(-1)[0]))
            first, steps = False, steps + 1
            max_x = max(max_x, abs(float(obs[0])))
            if terminated:
                end = "x" if abs(float(obs[0])) > X_LIMIT else "angle"
            if terminated or truncated:
                break
        drift = float(np.mean(path[len(path) // 2:]))  # where the second half of the episode was spent
        yield {"episode": ep, "length": steps, "end": end, "max_abs_x": round(max_x, 3),
               "side": "right" if drift > 0 else "left", "mean_x_second_half": round(drift, 3)}
    env.close()
    x, v = np.asarray(xs), np.asarray(values)
    bins = []
    for lo, hi in zip(X_BINS[:-1], X_BINS[1:]):
        sel = (x >= lo) & (x < hi)
        bins.append({"abs_x": f"{lo}-{hi}", "steps": int(sel.sum()),
                     "mean_value": round(float(v[sel].mean()), 2) if sel.any() else None})
    yield {"summary": True, "run_version": version, "explore": explore, "episodes": episodes,
           "value_by_abs_x": bins}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wmdist.bench.cartpole_probe", description=__doc__.split("\n")[0])
    ap.add_argument("run_dir")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--explore", action="store_true", help="sample the actor, as the collectors do")
    args = ap.parse_args(argv)
    if args.episodes < 1:
        print(f"wmdist: error: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    try:
        for line in probe(args.run_dir, args.episodes, args.explore):
            print(json.dumps(line), flush=True)
    except ConfigError as err:
        print(f"wmdist: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
