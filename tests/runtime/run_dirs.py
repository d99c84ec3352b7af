"""Run directories with a real checkpoint, made without Ray (for CLI tests of resume, dream, eval)."""
from __future__ import annotations

from pathlib import Path

from wmdist.config.loader import dump_yaml, load_config
from wmdist.runtime.checkpoint import save_checkpoint

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def run_dir_with_checkpoint(tmp_path: Path, preset: str, overrides: list[str] | None = None) -> Path:
    """tmp_path/run holding the preset's resolved config and one checkpoint of its real learner."""
    from wmdist.runtime.roles.setup import build_algorithm
    from wmdist.runtime.train import env_spec_or_error

    cfg = load_config(str(CONFIGS / f"{preset}.yaml"), [f"run.dir={tmp_path}", *(overrides or [])])
    learner = build_algorithm(cfg, env_spec_or_error(cfg), 0).make_learner("cpu")
    run_dir = tmp_path / "run"
    run_dir.mkdir(parents=True)
    (run_dir / "config.yaml").write_text(dump_yaml(cfg))
    state = {"learner": learner.state_dict(), "updates": 5, "version": 1, "nan_skips": 0, "sampled_sequences": 0}
    save_checkpoint(run_dir, state, learner.get_weights(), 1, {"updates": 5, "env_steps": 100}, None, keep=2)
    return run_dir
