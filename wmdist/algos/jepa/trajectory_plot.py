"""The embedding-space picture of one planned episode (JEPA has no decoder to dream with).

The policy plans toward the goal at every step; beside the real embeddings of the frames it
reaches, each decision's plan is rolled out by the predictor (the trajectory it expects), and
all of them, with the goal image's embedding, are projected on the first two principal
components of the real ones and the goal's.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from wmdist.algos.base import Weights
from wmdist.algos.jepa.planning import rollout
from wmdist.envs.env import Env

if TYPE_CHECKING:
    from wmdist.algos.jepa.algo import Jepa


def planned_episode(algo: "Jepa", weights: Weights, env: Env, steps: int) -> dict[str, np.ndarray | bool]:
    """Play one greedy episode of at most `steps` steps; returns the real embeddings [T+1, D],
    the predicted ones of each decision [T, H, D], the goal's [D] and whether it was reached."""
    policy = algo.make_policy("cpu")
    policy.set_weights(weights, 1)
    obs, first = env.reset(), True
    real, planned, reached = [], [], False
    with torch.no_grad():
        z, z_goal = policy.model.encode_obs(torch.as_tensor(obs[None]))
        real.append(z[0])
        for _ in range(steps):
            action = policy.act(obs[None], np.array([first]), None, None, explore=False)[0][0]
            assert policy.plan_from is not None and policy.plan is not None
            planned.append(rollout(policy.model, *policy.plan_from, policy.plan)[0])  # [H, D] what the plan expects
            obs, reward, terminated, truncated = env.step(action)
            first = False
            real.append(policy.model.encode_obs(torch.as_tensor(obs[None]))[0][0])
            if terminated or truncated:
                reached = reward > 0
                break
    return {"real": torch.stack(real).numpy(), "planned": torch.stack(planned).numpy(), "goal": z_goal[0].numpy(),
            "reached": reached}


def plot_planned_episode(algo: "Jepa", weights: Weights, env: Env, path: str, steps: int = 30) -> str:
    """Write the PNG (see the module doc) to `path` and return it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ep = planned_episode(algo, weights, env, steps)
    real, planned, goal = ep["real"], ep["planned"], ep["goal"]
    basis = np.concatenate([real, goal[None]])  # [T+2, D]
    mean = basis.mean(0)
    _, _, vt = np.linalg.svd(basis - mean, full_matrices=False)
    proj = lambda x: (x - mean) @ vt[:2].T  # noqa: E731  [..., 2]
    fig, ax = plt.subplots(figsize=(6, 5))
    for i, p in enumerate(proj(planned)):
        ax.plot(*np.concatenate([proj(real[i])[None], p]).T, "--", color="tab:orange", alpha=0.5,
                label="planned (predictor)" if i == 0 else None)
    r = proj(real)
    ax.plot(r[:, 0], r[:, 1], "o-", color="tab:blue", label="real (encoder)")
    ax.plot(*proj(goal), "*", color="tab:red", markersize=16, label="goal image")
    ax.set_title(f"JEPA embeddings, PCA ({len(real) - 1} steps, {'reached' if ep['reached'] else 'not reached'})")
    ax.set_xlabel("PC 1")
    ax.set_ylabel("PC 2")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """`python -m wmdist.algos.jepa.trajectory_plot RUN_DIR [OUT.png]`: the plot for a run's last
    checkpoint (until `wmdist dream` calls `embedding_plot` for algorithms without a decoder)."""
    import sys
    from pathlib import Path

    from wmdist.envs.factory import make_env
    from wmdist.runtime.evaluate import load_run

    torch.set_num_threads(1)  # small batched calls: a second thread only waits on a shared machine
    args = sys.argv[1:] if argv is None else argv
    if not args:
        print("usage: python -m wmdist.algos.jepa.trajectory_plot RUN_DIR [OUT.png]", file=sys.stderr)
        return 2
    cfg, _, algo, _, weights, _ = load_run(args[0])
    out = args[1] if len(args) > 1 else str(Path(args[0]) / "dream.png")
    print(f"wmdist: embedding plot {algo.embedding_plot(weights, make_env(cfg.env, cfg.run.seed + 17), out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
