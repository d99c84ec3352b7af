"""Why a Dreamer agent's CartPole-v1 episodes end, and whether its critic sees it coming (issue 24).

    python -m wmdist.bench.cartpole_probe RUN_DIR [--episodes 10] [--explore]

Plays episodes with the run's latest checkpoint (the actor's mode unless --explore) and prints one
JSON line per episode: its length, how it ended (`x`: the cart left the track, |x| > 2.4; `angle`: the
pole fell past 12 degrees; `limit`: 500 steps), the furthest the cart got and the side it drifted to.
Each ended episode also gives `cont_at_end`, the world model's continue probability at its terminal
observation. A last line gives the critic's mean value over every step, binned by |x|, and the ends
of the episodes in the checkpoint's replay (what the world model learned terminations from). A model
whose replay holds no cart-off-the-track ends predicts ~1 there, its imagination never ends an
episode at the edge, the critic's bins stay flat, and the actor has no reason to re-centre the cart.
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


def _critic(policy, ckpt):
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


def _ends(obs: np.ndarray, terminal: np.ndarray) -> dict[str, int]:
    """Terminal observations [n, 4] by cause: the cart off the track, else the pole fallen."""
    x_end = np.abs(obs[terminal, 0]) > X_LIMIT
    return {"x": int(x_end.sum()), "angle": int((~x_end).sum())}


def replay_ends(ckpt) -> dict | None:
    """How the episodes stored in a checkpoint's in-memory replay ended (None: no readable rows there,
    e.g. the redis backend keeps its records in redis)."""
    total: dict[str, int] = {"x": 0, "angle": 0, "steps": 0}
    found = False
    for f in sorted((ckpt / "replay").glob("shard*.npz")):
        with np.load(f, allow_pickle=False) as d:  # stored data is never unpickled
            if not {"f_obs", "f_terminal", "mask"} <= set(d.files):
                continue
            found = True
            valid = d["mask"].astype(bool)  # [N, T]
            for k, v in _ends(d["f_obs"], d["f_terminal"].astype(bool) & valid).items():
                total[k] += v
            total["steps"] += int(valid.sum())
    return total if found else None


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
    value_of = _critic(policy, ckpt)
    env = make_env(cfg.env, seed)
    xs, values = [], []  # every step of every episode: x [n] and the critic's value [n]
    for ep in range(episodes):
        obs, first, end, cont_end = env.reset(seed + ep), True, "limit", None
        path = []  # x at every decision of this episode
        while True:
            action, _ = policy.act(obs[None], np.array([first]), None, None, explore)
            with torch.no_grad():  # the posterior state the action was chosen in (act keeps it)
                values.append(float(value_of(policy.h, policy.z).reshape(-1)[0]))
            path.append(float(obs[0]))
            obs, _, terminated, truncated = env.step(int(np.asarray(action).reshape(-1)[0]))
            first = False
            if terminated:
                end = "x" if abs(float(obs[0])) > X_LIMIT else "angle"
            if terminated and policy.cfg.cont_head:
                with torch.no_grad():  # the terminal observation through the filter, as replay trains on it
                    h, z = policy.wm.filter_step(policy.h, policy.z, policy.prev_action, torch.as_tensor(obs[None]),
                                                 torch.ones(1, 1), policy.generator)
                    cont_end = float(torch.sigmoid(policy.wm.heads({"h": h, "z": z}, upto="cont")["cont"].float()).reshape(-1)[0])
            if terminated or truncated:
                break
        xs.extend(path)
        drift = float(np.mean(path[len(path) // 2:]))  # where the second half of the episode was spent
        max_x = float(np.abs([*path, float(obs[0])]).max())  # the last observation too (off the track)
        yield {"episode": ep, "length": len(path), "end": end, "max_abs_x": round(max_x, 3),
               "side": "right" if drift > 0 else "left", "mean_x_second_half": round(drift, 3),
               "cont_at_end": None if cont_end is None else round(cont_end, 4)}
    env.close()
    x, v = np.abs(xs), np.asarray(values)
    bins = []
    for lo, hi in zip(X_BINS[:-1], X_BINS[1:]):
        sel = (x >= lo) & (x < hi)
        bins.append({"abs_x": f"{lo}-{hi}", "steps": int(sel.sum()),
                     "mean_value": round(float(v[sel].mean()), 2) if sel.any() else None})
    yield {"summary": True, "run_version": version, "explore": explore, "episodes": episodes,
           "value_by_abs_x": bins, "replay_ends": replay_ends(ckpt)}


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
    except BrokenPipeError:  # piped into head: the reader has what it wanted
        sys.stderr.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
