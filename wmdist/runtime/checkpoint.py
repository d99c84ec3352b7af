"""Checkpoints: learner state (weights + optimiser), published weights, counters, replay.

Layout: RUN_DIR/checkpoints/ckpt-<updates>/{learner.pt, weights.npz, counters.json, replay/}.
A checkpoint is written to a temporary folder and renamed, so a crash mid-write never
leaves a half checkpoint that resume would pick. Loading never unpickles code:
`torch.load(weights_only=True)` and `np.load(allow_pickle=False)`.
"""
from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch

from wmdist.config.errors import first_line

CKPT_DIR = "checkpoints"


def _tensorise(obj: Any) -> Any:
    """numpy arrays -> tensors so the file loads with weights_only=True."""
    if isinstance(obj, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(obj))
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, dict):
        return {k: _tensorise(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_tensorise(v) for v in obj)
    return obj


def save_checkpoint(run_dir: str | Path, learner_state: dict, weights: dict[str, np.ndarray], version: int,
                    counters: dict, replay: Any | None, keep: int) -> Path:
    root = Path(run_dir) / CKPT_DIR
    root.mkdir(parents=True, exist_ok=True)
    name = f"ckpt-{int(counters.get('updates', 0)):09d}-{int(counters.get('env_steps', 0)):012d}"
    final = root / name
    tmp = root / f".{name}.tmp"
    clean_partial(run_dir)
    tmp.mkdir()
    torch.save(_tensorise(learner_state), tmp / "learner.pt")
    np.savez(tmp / "weights.npz", **{k: np.asarray(v) for k, v in weights.items()})
    (tmp / "counters.json").write_text(json.dumps({**counters, "version": int(version)}, indent=1))
    if replay is not None:
        replay.save(str(tmp / "replay"))
    aside = root / f".{name}.old.tmp"  # a checkpoint of the same counters (rewritten at the end of a run)
    if final.exists():
        # moved aside in one rename, never deleted in place: a reader (`wmdist eval`, a resume)
        # that found `final` must not see it half-removed
        shutil.rmtree(aside, ignore_errors=True)
        final.rename(aside)
    tmp.rename(final)
    shutil.rmtree(aside, ignore_errors=True)
    for old in list_checkpoints(run_dir)[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    return final


def clean_partial(run_dir: str | Path) -> int:
    """Remove the temporary folders of checkpoints whose write never finished (a crash or a
    kill mid-write); returns how many there were."""
    root = Path(run_dir) / CKPT_DIR
    stale = list(root.glob(".ckpt-*.tmp")) if root.is_dir() else []
    for p in stale:
        shutil.rmtree(p, ignore_errors=True)
    return len(stale)


def list_checkpoints(run_dir: str | Path) -> list[Path]:
    root = Path(run_dir) / CKPT_DIR
    if not root.is_dir():
        return []
    return sorted(p for p in root.iterdir() if p.is_dir() and p.name.startswith("ckpt-"))


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    ckpts = list_checkpoints(run_dir)
    return ckpts[-1] if ckpts else None


def unreadable_message(ckpt: Path, err: BaseException) -> str:
    """One line for a checkpoint that fails to load, naming the older one a user can fall back to
    (checkpoints are renamed into place whole, so damage means the disk or a hand edit)."""
    older = [p for p in list_checkpoints(ckpt.parent.parent) if p.name < ckpt.name]
    hint = (f"; move it aside to use the previous one, {older[-1].name}" if older
            else "; there is no older checkpoint to fall back to")
    return f"{ckpt} cannot be read ({first_line(err)}){hint}"


def load_counters(ckpt: Path) -> dict:
    return json.loads((ckpt / "counters.json").read_text())


def load_learner_state(ckpt: Path) -> dict:
    with warnings.catch_warnings():
        # a damaged or foreign file warns about its pickle protocol before it fails: the failure is
        # reported as one line by the caller, and the warning would only add noise around it
        warnings.filterwarnings("ignore", message="Detected pickle protocol")
        return torch.load(ckpt / "learner.pt", weights_only=True, map_location="cpu")


def load_weights(ckpt: Path) -> tuple[int, dict[str, np.ndarray]]:
    with np.load(ckpt / "weights.npz", allow_pickle=False) as data:
        weights = {k: data[k] for k in data.files}
    return int(load_counters(ckpt)["version"]), weights
