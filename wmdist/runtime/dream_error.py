"""`wmdist dream RUN_DIR --error`: the world model's open-loop prediction error by horizon,
beside predicting "no change" (`wmdist/algos/dream_error.py`), on greedy episodes of the run's
own policy. Prints a table and writes RUN_DIR/dream_error.json."""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import IO

import torch

from wmdist.algos.base import MEASURES_PREDICTION
from wmdist.algos.dream_error import HorizonError, add_episode_errors, default_horizons, format_errors
from wmdist.algos.dream_video import play_greedy
from wmdist.config.errors import ConfigError
from wmdist.runtime.evaluate import load_run

MAX_EPISODE_STEPS = 1000  # a longer episode is measured on its first 1,000 steps


def dream_error_run(run_dir: str, episodes: int = 5, horizon: int = 16, stride: int = 1,
                    stream: IO[str] | None = None) -> int:
    stream = stream or sys.stdout
    cfg, spec, algo, version, weights, ckpt = load_run(run_dir)
    if not algo.offers(MEASURES_PREDICTION):
        raise ConfigError(f"dream --error measures an RSSM world model's open-loop predictions (Dreamer, PlaNet); "
                          f"{run_dir} trained {cfg.algo_name!r}")
    from wmdist.envs.factory import make_env

    wm = algo.world_model(weights).eval()
    errors = {k: HorizonError(k) for k in default_horizons(horizon)}
    env = make_env(cfg.env, cfg.run.seed + 23)
    generator = torch.Generator().manual_seed(cfg.run.seed)  # latents sampled, as the model imagines
    steps = 0
    for ep in range(episodes):
        obs, actions = play_greedy(algo, weights, env, MAX_EPISODE_STEPS, cfg.run.seed + 23 + ep)
        add_episode_errors(wm, spec, obs, actions, errors, stride, generator)
        steps += len(obs)
    dims = ["pixels"] if spec.obs_kind == "image" else [f"obs[{i}]" for i in range(spec.obs_shape[0])]
    print(f"dream error: {ckpt.name}, {episodes} greedy episodes ({steps} steps), RMS error of the model's open-loop "
          f"prediction / of predicting no change, by horizon k", file=stream)
    for line in format_errors(errors, dims):
        print(line, file=stream)
    rows = []
    for k, e in sorted(errors.items()):
        if e.count:
            model, still = e.rms()
            rows.append({"horizon": k, "starts": e.count, "model_rms": model.tolist(), "no_change_rms": still.tolist()})
    out = Path(run_dir) / "dream_error.json"
    out.write_text(json.dumps({"checkpoint": ckpt.name, "version": version, "episodes": episodes, "steps": steps,
                               "dims": dims, "rows": rows}, indent=1) + "\n")
    print(f"wmdist: dream error {out}", file=stream)
    return 0
