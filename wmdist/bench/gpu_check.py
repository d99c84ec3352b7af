"""`make gpu-check`: every preset's learner and collector on CUDA for a short fixed budget.

Per preset (in configs/, shrunk where the network is paper-sized): a local session (no Ray)
with the collector and learner on CUDA collects a few segments (env steps/s), then a CPU
learner and a CUDA learner built with the same seed take one update on the same batch and
their losses are compared, and the CUDA learner runs for a fixed time (updates/s). One JSON
line per preset, then a summary line; exit status 1 if any preset failed.

The two losses come from different random streams on the two devices (latent samples,
imagination), so the comparison catches a wrong device or dtype path, not last bits:
`LOSS_TOL` relative. Without a CUDA device it prints one line and exits 0.

    python -m wmdist.bench.gpu_check [--seconds S] [PRESET ...]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from pathlib import Path

CONFIGS = Path(__file__).parents[2] / "configs"
LOSS_TOL = 0.1  # relative |cpu - cuda| / |cpu|
TOTAL_SECONDS = 420.0  # presets left when this is spent are reported as skipped (make's budget: 8 min)
# every preset: small batches and windows, a short warm-up, one collector with few envs
COMMON = ["learner.gpus=1", "actors.gpus=1", "actors.num=1", "actors.envs_per_actor=2", "actors.segment_steps=20",
          "learner.batch_size=4", "replay.min_size=1", "eval.every_seconds=0", "metrics.enabled=false",
          "checkpoint.every_seconds=0"]
# per preset: what keeps its CPU reference update and collection short (the tests' smoke sizes)
SHRINK = {
    "muzero_atari.yaml": ["algo.conv_channels=8", "algo.conv_blocks=1", "algo.hidden=[16]",
                          "algo.search.num_simulations=2", "algo.value_support=20", "algo.reward_support=5"],
    "efficientzero_atari.yaml": ["algo.conv_channels=8", "algo.hidden=[16]", "algo.search.num_simulations=2",
                                 "algo.value_support=20", "algo.reward_support=5", "algo.lstm_hidden=16",
                                 "algo.proj_hidden=16", "algo.proj_dim=16", "algo.pred_hidden=8"],
    "planet_dmc_cartpole_swingup.yaml": ["algo.planner.candidates=20", "algo.planner.top_k=4", "algo.planner.iterations=2"],
    "planet_dmc_cartpole_swingup_pixels.yaml": ["algo.planner.candidates=20", "algo.planner.top_k=4",
                                                "algo.planner.iterations=2"],
}
SEQUENCE = ["replay.seq_len=16"]  # presets that replay windows (Dreamer family, PlaNet)


def presets() -> list[str]:
    return sorted(p.name for p in CONFIGS.glob("*.yaml") if p.name != "base.yaml")


def _loss_key(metrics: dict[str, float]) -> str:
    for key in ("loss", "model_loss"):
        if key in metrics:
            return key
    return sorted(k for k in metrics if k.endswith("loss"))[0]


def check_preset(name: str, seconds: float, device: str = "cuda") -> dict:
    import torch

    from wmdist.config.loader import load_config
    from wmdist.runtime.local import LocalSession
    from wmdist.runtime.roles.setup import build_algorithm

    over = COMMON + SHRINK.get(name, []) + (SEQUENCE if name.startswith(("dreamer", "planet")) else [])
    cfg = load_config(CONFIGS / name, over)
    session = LocalSession(cfg)
    try:
        t0 = time.perf_counter()
        segments = 0
        while segments < 3 or session.stored_count() < 2:
            session.collect(1)
            segments += 1
            if segments >= 3 and time.perf_counter() - t0 > 120:
                raise RuntimeError(f"replay holds {session.stored_count()} sequences after {segments} segments")
        env_steps_per_s = session.env_steps / (time.perf_counter() - t0)
        batch = session.sample(cfg.learner.batch_size)
        losses = {}
        for where in ("cpu", device):  # same seed: same initial weights on both
            learner = build_algorithm(cfg, session.spec, cfg.run.seed).make_learner(where)
            m = learner.update(batch).metrics
            losses[where] = float(m[_loss_key(m)])
        key = _loss_key(m)
        sync = torch.cuda.synchronize if device == "cuda" else (lambda: None)
        sync()
        t0, updates = time.perf_counter(), 0
        while time.perf_counter() - t0 < seconds:
            learner.update(session.sample(cfg.learner.batch_size))
            updates += 1
        sync()
        rel = abs(losses["cpu"] - losses[device]) / max(abs(losses["cpu"]), 1e-6)
        return {"preset": name, "ok": rel <= LOSS_TOL, "loss_key": key, "loss_cpu": round(losses["cpu"], 5),
                f"loss_{device}": round(losses[device], 5), "rel_diff": round(rel, 4),
                "updates_per_s": round(updates / (time.perf_counter() - t0), 2),
                "env_steps_per_s": round(env_steps_per_s, 1)}
    finally:
        session.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wmdist.bench.gpu_check", description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="timed CUDA updates per preset")
    ap.add_argument("--device", default="cuda", help=argparse.SUPPRESS)  # cpu: a self-test of this script
    ap.add_argument("presets", nargs="*", help="preset file names (default: every preset in configs/)")
    args = ap.parse_args(argv)
    import torch

    if args.device == "cuda" and not torch.cuda.is_available():
        print("gpu-check: skipped, no CUDA device here (torch.cuda.is_available() is False)")
        return 0
    start, failed, results = time.perf_counter(), [], []
    for name in args.presets or presets():
        if time.perf_counter() - start > TOTAL_SECONDS:
            out = {"preset": name, "ok": None, "skipped": f"time budget of {TOTAL_SECONDS:.0f} s spent"}
        else:
            try:
                out = check_preset(name, args.seconds, args.device)
            except Exception as e:  # one preset's failure must not hide the others'
                out = {"preset": name, "ok": False, "error": f"{type(e).__name__}: {e}"[:300]}
                traceback.print_exc(file=sys.stderr)  # stdout stays one JSON line per preset; the stack goes to stderr
        if out["ok"] is False:
            failed.append(name)
        results.append(out)
        print(json.dumps(out), flush=True)
    done = sum(r["ok"] is not None for r in results)
    print(f"gpu-check: {done - len(failed)}/{done} presets ok on {torch.cuda.get_device_name() if args.device == 'cuda' else args.device}"
          f"{' (failed: ' + ', '.join(failed) + ')' if failed else ''} in {time.perf_counter() - start:.0f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
