"""Bad input to `wmdist train`: one line on stderr, exit status 2, nothing started or written.

Each case runs the real CLI in-process; none gets as far as starting Ray (the checks run
first), so a case that did would be slow and would leave a run directory behind.
"""
from __future__ import annotations

import shutil
import socket
from pathlib import Path

import numpy as np
import pytest

from tests.runtime.run_dirs import run_dir_with_checkpoint
from tests.runtime.one_line import one_line_exit_2
from wmdist.runtime.checkpoint import CKPT_DIR, clean_partial, latest_checkpoint, save_checkpoint

ROOT = Path(__file__).resolve().parents[2]
FAKE = str(Path(__file__).parent / "fake.yaml")
MUZERO = str(ROOT / "configs" / "muzero_cartpole.yaml")


def _one_line_exit_2(capsys, argv: list[str]) -> str:
    return one_line_exit_2(capsys, argv)[0]


@pytest.fixture
def busy_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def test_busy_metrics_port_fails_before_anything_starts(tmp_path, capsys, busy_port):
    line = _one_line_exit_2(capsys, ["train", FAKE, "--set", f"run.dir={tmp_path}", "metrics.enabled=true",
                                     f"metrics.port={busy_port}"])
    assert f"metrics.port {busy_port}" in line
    assert not any(tmp_path.iterdir()), "a run directory was created"


def test_more_cpus_than_the_machine_fails_before_ray_starts(tmp_path, capsys):
    line = _one_line_exit_2(capsys, ["train", FAKE, "--set", f"run.dir={tmp_path}", "actors.num=64",
                                     "actors.cpus=1"])
    assert "CPU" in line and "actors.num" in line
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("config, sets", [
    (MUZERO, ["run.stop_at_lost_lines=0"]),  # CartPole has no game tree to judge
    (str(ROOT / "configs" / "muzero_tictactoe.yaml"), ["run.stop_at_lost_lines=-1"]),
])
def test_stop_at_lost_lines_without_a_judge_is_one_line(tmp_path, capsys, config, sets):
    line = _one_line_exit_2(capsys, ["train", config, "--set", f"run.dir={tmp_path}", *sets])
    assert "run.stop_at_lost_lines" in line
    assert not any(tmp_path.iterdir())


def test_uncreatable_run_dir_is_one_line(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    line = _one_line_exit_2(capsys, ["train", FAKE, "--set", f"run.dir={blocker}/runs"])
    assert "run.dir" in line


@pytest.mark.parametrize("url, message", [
    ("127.0.0.1:6379", "must start with redis://"),
    ("redis://127.0.0.1:{closed}/0", "nothing answers there"),
])
def test_unreachable_redis_is_one_line(tmp_path, capsys, url, message):
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        closed = s.getsockname()[1]
    line = _one_line_exit_2(capsys, ["train", FAKE, "--set", f"run.dir={tmp_path}", "replay.backend=redis",
                                     f"replay.redis_url={url.format(closed=closed)}"])
    assert message in line
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("address, message", [
    ("headnode", "expected 'auto', HOST:PORT"),
    ("127.0.0.1:{closed}", "nothing answers there"),
    ("ray://127.0.0.1:{closed}", "nothing answers there"),
])
def test_unreachable_ray_address_is_one_line_before_anything_starts(tmp_path, capsys, address, message):
    with socket.socket() as s:  # a port that was free a moment ago: no head listens there
        s.bind(("127.0.0.1", 0))
        closed = s.getsockname()[1]
    line = _one_line_exit_2(capsys, ["train", FAKE, "--set", f"run.dir={tmp_path}",
                                     f"ray.address={address.format(closed=closed)}"])
    assert message in line
    assert not any(tmp_path.iterdir()), "a run directory was created"


def test_redis_password_problems_are_one_line(tmp_path, capsys):
    from wmdist.replay.redis_server import RedisServer

    server = RedisServer(str(tmp_path / "redis")).start()
    try:
        wrong = tmp_path / "wrong.pass"
        wrong.write_text("not-the-password")
        base = ["train", FAKE, "--set", f"run.dir={tmp_path / 'runs'}", "replay.backend=redis",
                f"replay.redis_url={server.url}"]
        assert "password was refused" in _one_line_exit_2(capsys, base + [f"replay.redis_password_file={wrong}"])
        assert "wants a password" in _one_line_exit_2(capsys, base)
        missing = tmp_path / "missing.pass"
        assert "no such file" in _one_line_exit_2(capsys, base + [f"replay.redis_password_file={missing}"])
    finally:
        server.stop()
    assert not (tmp_path / "runs").exists()


def test_config_with_resume_is_refused(tmp_path, capsys):
    assert "not both" in _one_line_exit_2(capsys, ["train", FAKE, "--resume", str(tmp_path)])


def _muzero_run(tmp_path: Path, overrides: list[str] | None = None) -> Path:
    return run_dir_with_checkpoint(tmp_path, "muzero_cartpole", overrides)


def test_resume_that_changes_the_model_is_refused_and_leaves_the_run_as_it_was(tmp_path, capsys):
    run_dir = _muzero_run(tmp_path)
    before = (run_dir / "config.yaml").read_text()
    line = _one_line_exit_2(capsys, ["train", "--resume", str(run_dir), "--set", "algo.hidden=[32]"])
    assert "does not fit the model" in line
    line = _one_line_exit_2(capsys, ["train", "--resume", str(run_dir), "--set", "env.id=board:tictactoe"])
    assert (run_dir / "config.yaml").read_text() == before, "a failed resume rewrote config.yaml"
    assert sorted(p.name for p in run_dir.iterdir()) == [CKPT_DIR, "config.yaml"]


def test_checkpoint_of_another_model_is_one_line(tmp_path, capsys):
    run_dir = _muzero_run(tmp_path / "a")
    other = _muzero_run(tmp_path / "b", ["algo.hidden=[16, 16]"])
    ckpt = latest_checkpoint(run_dir)
    shutil.rmtree(ckpt)
    shutil.copytree(latest_checkpoint(other), ckpt)  # someone copied the wrong checkpoint in
    assert "does not fit the model" in _one_line_exit_2(capsys, ["train", "--resume", str(run_dir)])


def test_unreadable_checkpoint_is_one_line(tmp_path, capsys):
    run_dir = _muzero_run(tmp_path)
    (latest_checkpoint(run_dir) / "learner.pt").write_bytes(b"\x80\x04not a checkpoint")
    assert "cannot be read" in _one_line_exit_2(capsys, ["train", "--resume", str(run_dir)])


def _with_replay(run_dir: Path) -> Path:
    """Give the run's checkpoint the replay files a real run writes (one empty shard of the preset's size)."""
    from wmdist.config.loader import load_config
    from wmdist.replay.shard import ReplayShard
    from wmdist.runtime.replay_client import shard_capacity
    from wmdist.runtime.roles.setup import build_algorithm
    from wmdist.runtime.train import env_spec_or_error

    cfg = load_config(str(run_dir / "config.yaml"), [])
    fields = build_algorithm(cfg, env_spec_or_error(cfg), 0).step_fields()
    folder = latest_checkpoint(run_dir) / "replay"
    folder.mkdir()
    ReplayShard(fields, cfg.replay.seq_len, shard_capacity(cfg.replay, fields)).save(str(folder / "shard0.npz"))
    (folder / "limiter.json").write_text('{"inserted": 0, "sampled": 0}')
    return folder


def test_damaged_or_mismatched_replay_in_a_checkpoint_is_one_line_before_ray(tmp_path, capsys):
    run_dir = _muzero_run(tmp_path)
    folder = _with_replay(run_dir)
    before = sorted(p.name for p in run_dir.iterdir())
    for argv_tail, expect in ((["--set", "replay.shards=2"], "replay.shards=2"),
                              (["--set", "replay.capacity_steps=5000"], "cannot change on resume")):
        assert expect in _one_line_exit_2(capsys, ["train", "--resume", str(run_dir), *argv_tail])
    shard = folder / "shard0.npz"
    shard.write_bytes(shard.read_bytes()[:200])  # cut short: a full disk, a killed copy
    assert "cannot be read" in _one_line_exit_2(capsys, ["train", "--resume", str(run_dir)])
    (folder / "limiter.json").write_text("[1, 2")
    assert "cannot be read" in _one_line_exit_2(capsys, ["train", "--resume", str(run_dir)])
    assert sorted(p.name for p in run_dir.iterdir()) == before  # nothing written: no log, no metrics


def test_half_written_checkpoints_are_cleaned_up(tmp_path):
    w = {"w": np.zeros((2, 2), np.float32)}
    save_checkpoint(tmp_path, {"w": w["w"]}, w, 1, {"updates": 1, "env_steps": 1}, None, keep=2)
    stale = tmp_path / CKPT_DIR / ".ckpt-000000009-000000000009.tmp"
    stale.mkdir()
    (stale / "learner.pt").write_bytes(b"partial")
    save_checkpoint(tmp_path, {"w": w["w"]}, w, 2, {"updates": 2, "env_steps": 2}, None, keep=2)
    assert not stale.exists()
    stale.mkdir()
    assert clean_partial(tmp_path) == 1 and not stale.exists()


def test_a_checkpoint_rewritten_at_the_same_counters_is_replaced_whole(tmp_path, monkeypatch):
    # it used to be deleted in place before the new one was renamed in: a reader (eval, a test
    # polling for checkpoints) could find the folder without its counters.json
    import shutil

    from wmdist.runtime import checkpoint as ck

    w = {"w": np.zeros((2, 2), np.float32)}
    first = save_checkpoint(tmp_path, {"w": w["w"]}, w, 1, {"updates": 0, "env_steps": 0}, None, keep=2)
    seen, real_rmtree = [], shutil.rmtree

    def rmtree(path, *args, **kwargs):  # after anything is deleted, the checkpoint is there, whole
        real_rmtree(path, *args, **kwargs)
        seen.append((first / "counters.json").exists())

    monkeypatch.setattr(ck.shutil, "rmtree", rmtree)
    again = save_checkpoint(tmp_path, {"w": w["w"]}, w, 7, {"updates": 0, "env_steps": 0}, None, keep=2)
    assert again == first and ck.load_counters(first)["version"] == 7
    assert seen and all(seen)
    assert [p.name for p in (tmp_path / CKPT_DIR).iterdir()] == [first.name]  # nothing set aside is left
