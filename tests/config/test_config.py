"""Config loading: overlays, --set precedence, and one-line errors for every kind of mistake."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from wmdist.cli import main
from wmdist.config.errors import ConfigError
from wmdist.config.loader import dump_yaml, load_config

DATA = Path(__file__).parent / "data"
CHILD = str(DATA / "child.yaml")


def test_overlays_and_set_precedence():
    cfg = load_config(CHILD)
    assert cfg.run.seed == 1 and cfg.run.max_env_steps == 100  # from base
    assert cfg.actors.num == 3  # child overrides base
    assert cfg.actors.cpus == 0.5  # base value kept where the child is silent
    assert cfg.learner.batch_size == 8
    assert cfg.algo.lr == 0.1 and cfg.algo_name == "tests.runtime.fake_algo:FakeAlgo"
    cfg = load_config(CHILD, ["actors.num=5", "algo.lr=0.2", "actors.num=6", "run.name=x"])
    assert cfg.actors.num == 6 and cfg.algo.lr == 0.2 and cfg.run.name == "x"  # last --set wins


def test_resolved_config_round_trips(tmp_path):
    cfg = load_config(CHILD, ["replay.overlap=2"])
    (tmp_path / "c.yaml").write_text(dump_yaml(cfg))
    again = load_config(tmp_path / "c.yaml")
    assert dump_yaml(again) == dump_yaml(cfg)
    assert yaml.safe_load(dump_yaml(cfg))["algo"]["name"] == "tests.runtime.fake_algo:FakeAlgo"


@pytest.mark.parametrize("override, message", [
    ("actors.nmu=2", "unknown key 'actors.nmu' (did you mean 'actors.num'?)"),
    ("actros.num=2", "unknown key 'actros' (did you mean 'actors'?)"),
    ("actors.num=abc", "actors.num: expected int, got str 'abc'"),
    ("actors.num=0", "actors.num: 0 is out of range (must be >= 1)"),
    ("learner.cpus=-1", "learner.cpus: -1.0 is out of range (must be > 0)"),
    ("replay.sampler=fifo", "replay.sampler: 'fifo' is not one of 'uniform', 'prioritized'"),
    ("algo.lr=-3", "algo.lr: -3.0 is out of range (must be > 0)"),
    ("algo.name=muzer", "unknown algorithm 'muzer' (did you mean 'muzero'?)"),
    ("actors.num=1.5", "actors.num: expected int, got float 1.5"),
    ("replay.overlap=8", "replay.overlap"),
])
def test_config_errors_are_one_line(override, message):
    with pytest.raises(ConfigError) as err:
        load_config(CHILD, [override])
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("actors: {num: [1,\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(bad)
    (tmp_path / "noalgo.yaml").write_text("actors: {num: 1}\n")
    with pytest.raises(ConfigError, match="algo.name is missing"):
        load_config(tmp_path / "noalgo.yaml")


def test_cli_errors_exit_2_with_one_line(capsys):
    assert main(["config", CHILD, "--set", "actors.num=0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wmdist: error: actors.num: 0 is out of range") and err.count("\n") == 1
    assert main(["config", "does/not/exist.yaml"]) == 2
    assert "config file not found" in capsys.readouterr().err
    assert main(["train", CHILD, "--set", "env.id=gym:CartPol-v1"]) == 2
    err = capsys.readouterr().err
    assert "CartPole-v1" in err and err.count("\n") == 1


def test_cli_config_prints_resolved_yaml(capsys):
    assert main(["config", CHILD, "--set", "actors.envs_per_actor=4"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["actors"]["envs_per_actor"] == 4 and printed["actors"]["num"] == 3
    assert main(["config", CHILD, "--docs"]) == 0
    docs = capsys.readouterr().out
    assert "actors.num" in docs and "number of collector actors" in docs and "algo.lr" in docs


def test_a_preset_copied_out_of_configs_finds_its_defaults_among_the_presets(tmp_path):
    """Users copy a preset elsewhere and edit it: its `defaults: [base, ...]` still resolve
    (beside the file first, then the shipped presets), and it loads exactly as the original."""
    presets = Path(__file__).parents[2] / "configs"
    copy = tmp_path / "mine.yaml"
    copy.write_text((presets / "efficientzero_cartpole.yaml").read_text())  # defaults: [base, muzero_cartpole]
    assert dump_yaml(load_config(copy)) == dump_yaml(load_config(presets / "efficientzero_cartpole.yaml"))
    # a file beside the copy wins over the preset of the same name
    (tmp_path / "muzero_cartpole.yaml").write_text("defaults: [base]\nalgo: {name: muzero, td_steps: 7}\n")
    assert load_config(copy).algo.td_steps == 50  # the copy's own value still wins over both
    (tmp_path / "k.yaml").write_text("defaults: [muzero_cartpole]\nrun: {seed: 3}\n")
    assert load_config(tmp_path / "k.yaml").algo.td_steps == 7


@pytest.mark.parametrize("text, message", [
    ("defaults: [nosuch]\n", "defaults entry 'nosuch' names no config: no nosuch.yaml beside it"),
    ("defaults: 3\n", "defaults must be a list of config names, got int"),
    ("defaults: [[base]]\n", "defaults entries are config names (e.g. base), got ['base']"),
])
def test_bad_defaults_are_one_line(tmp_path, text, message):
    (tmp_path / "c.yaml").write_text(text)
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_config(tmp_path / "c.yaml")


def test_a_directory_given_as_the_config_is_one_line(tmp_path):
    (tmp_path / "a.yaml").write_text("run: {seed: 1}\n")
    with pytest.raises(ConfigError, match=re.escape("is a directory, not a config file (it holds a.yaml, ...)")):
        load_config(tmp_path)
    (tmp_path / "config.yaml").write_text("run: {seed: 1}\n")  # a run directory: say how to continue it
    with pytest.raises(ConfigError, match=re.escape(f"continue it with `wmdist train --resume {tmp_path}`")):
        load_config(tmp_path)
