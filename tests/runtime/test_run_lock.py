"""One `wmdist train` per run directory: a second resume while the first runs is one line and
exit 2, and the lock goes with its process, however that process ends."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.runtime.one_line import one_line_exit_2
from wmdist.config.errors import ConfigError
from wmdist.runtime import train as train_mod
from wmdist.runtime.run_lock import RunLock

MUZERO = str(Path(__file__).resolve().parents[2] / "configs" / "muzero_cartpole.yaml")
HOLD = "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDONLY); fcntl.flock(fd, fcntl.LOCK_EX); " \
       "print('held', flush=True); time.sleep(120)"


def test_a_resume_of_a_run_another_process_holds_is_refused_until_that_process_dies(tmp_path, capsys):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(run_dir)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        line, _ = one_line_exit_2(capsys, ["train", "--resume", str(run_dir)])
        assert "is in use by another wmdist train" in line
        assert not any(run_dir.iterdir()), "a refused resume wrote into the run directory"
    finally:
        holder.kill()  # as kill -9: no cleanup runs
        holder.wait()
    line, _ = one_line_exit_2(capsys, ["train", "--resume", str(run_dir)])
    assert "in use" not in line  # the lock died with its holder: the next check speaks now


def test_a_running_train_holds_its_new_run_directory_and_lets_go_at_the_end(tmp_path, monkeypatch):
    seen: dict[str, Path] = {}

    def run(cfg, spec, fields, run_dir, *args, **kwargs):
        seen["dir"] = run_dir
        with pytest.raises(ConfigError, match="in use"):
            RunLock(run_dir).acquire()  # what a second `wmdist train --resume` meets meanwhile
        return 0

    monkeypatch.setattr(train_mod, "_run", run)
    from wmdist.config.loader import load_config

    cfg = load_config(MUZERO, [f"run.dir={tmp_path}", "run.max_env_steps=10"])
    assert train_mod.train(cfg) == 0
    RunLock(seen["dir"]).acquire().release()  # released when train returned
