"""Bad input at the config's edges: repeated --set flags, numbers as people write them,
non-finite floats, list elements, bare dmc domains, env constructors that raise."""
from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

from wmdist.cli import _parser, main
from wmdist.config.errors import ConfigError
from wmdist.config.fields import param
from wmdist.config.loader import build, load_config, parse_yaml

DATA = Path(__file__).parent / "data"
CHILD = str(DATA / "child.yaml")
MUZERO = str(Path(__file__).parents[2] / "configs" / "muzero_cartpole.yaml")


def _one_line_error(overrides: list[str], path: str = CHILD) -> str:
    with pytest.raises(ConfigError) as err:
        load_config(path, overrides)
    msg = str(err.value)
    assert "\n" not in msg
    return msg


# --- 1. every --set flag counts ---------------------------------------------------------


def test_every_set_flag_counts_in_wmdist_config(capsys):
    assert main(["config", MUZERO, "--set", "run.dir=other_runs", "--set", "actors.num=2", "learner.batch_size=4"]) == 0
    out = capsys.readouterr().out
    assert "dir: other_runs" in out  # the first flag's list used to be dropped
    assert "num: 2" in out and "batch_size: 4" in out


def test_every_set_flag_counts_in_wmdist_train():
    a = _parser().parse_args(["train", "c.yaml", "--set", "a=1", "b=2", "--set", "c=3"])
    assert a.set == ["a=1", "b=2", "c=3"]


def test_every_set_flag_counts_in_the_learning_bench(tmp_path, monkeypatch, capsys):
    from wmdist.bench import learning

    cmds = []

    def fake_run(cmd, **kwargs):
        cmds.append(cmd)
        return subprocess.CompletedProcess(cmd, 1, "", "failed")

    monkeypatch.setattr(learning.subprocess, "run", fake_run)
    learning.main([MUZERO, "--seeds", "0", "--target", "1", "--png", str(tmp_path / "c.png"),
                   "--runs-dir", str(tmp_path), "--set", "learner.batch_size=4", "--set", "actors.num=1"])
    assert cmds and cmds[0][-2:] == ["learner.batch_size=4", "actors.num=1"]


def test_learning_bench_refuses_a_bad_config_before_any_run(tmp_path, monkeypatch, capsys):
    from wmdist.bench import learning

    monkeypatch.setattr(learning.subprocess, "run", lambda *a, **k: pytest.fail("a run was started"))
    for argv in ([MUZERO, "--set", "algo.horizon=-1"], ["missing.yaml"], [MUZERO, "--seeds", "-1"]):
        assert learning.main([*argv, "--target", "1", "--png", str(tmp_path / "c.png"),
                              "--runs-dir", str(tmp_path / "runs")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("wmdist: error: "), err
    assert not (tmp_path / "runs").exists() and not (tmp_path / "c.png").exists()


@pytest.mark.parametrize("extra, message", [
    (["--target", "nan"], "--target"),                  # NaN compares false: no run could ever be judged met
    (["--target", "1", "--budget-env-steps", "0"], "--budget-env-steps"),
    (["--target", "1", "--budget-minutes", "-2"], "--budget-minutes"),
])
def test_learning_bench_refuses_a_target_or_budget_it_cannot_judge(tmp_path, monkeypatch, capsys, extra, message):
    from wmdist.bench import learning

    monkeypatch.setattr(learning.subprocess, "run", lambda *a, **k: pytest.fail("a run was started"))
    assert learning.main([MUZERO, *extra, "--png", str(tmp_path / "c.png"), "--runs-dir", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"wmdist: error: {message}"), err


# --- 2. numbers as people write them ---------------------------------------------------


@pytest.mark.parametrize("text, value", [
    ("1e-4", 1e-4), ("3e5", 3e5), ("1E+3", 1e3), ("-2.5e-3", -2.5e-3), (".5", 0.5), ("-.5", -0.5),
    ("+3e2", 300.0), ("1.0e-8", 1e-8), ("1.5", 1.5),
])
def test_exponent_and_leading_dot_floats_are_floats(text, value):
    out = parse_yaml(text)
    assert isinstance(out, float) and out == value


@pytest.mark.parametrize("text, value", [("1_000", 1000), ("42", 42), ("-3", -3), ("0x10", 16)])
def test_ints_stay_ints(text, value):
    out = parse_yaml(text)
    assert type(out) is int and out == value


@pytest.mark.parametrize("text", ["1e", "e5", "abc", "1.2.3"])
def test_non_numbers_stay_strings(text):
    assert isinstance(parse_yaml(text), str)


def test_set_and_yaml_files_read_exponent_floats(tmp_path):
    cfg = load_config(CHILD, ["algo.lr=1e-4", "actors.num=3e0", "replay.capacity_steps=3e5"])
    assert cfg.algo.lr == 1e-4
    assert cfg.actors.num == 3 and type(cfg.actors.num) is int  # an integral float fills an int field
    assert cfg.replay.capacity_steps == 300_000 and type(cfg.replay.capacity_steps) is int
    path = tmp_path / "c.yaml"
    path.write_text(f"defaults: [{DATA / 'base'}]\nenv: {{id: gym:CartPole-v1}}\n"
                    "algo: {name: 'tests.runtime.fake_algo:FakeAlgo', lr: 1e-4}\nlearner: {cpus: .5}\n")
    cfg = load_config(path)
    assert cfg.algo.lr == 1e-4 and cfg.learner.cpus == 0.5


def test_run_dir_config_reads_exponent_floats(tmp_path):
    from wmdist.runtime.train import CONFIG_FILE, load_run_config

    (tmp_path / CONFIG_FILE).write_text((DATA / "child.yaml").read_text().replace("defaults: [base]\n", "")
                                        .replace("lr: 0.1", "lr: 1e-4"))
    assert load_run_config(tmp_path).algo.lr == 1e-4


# --- 3. non-finite floats --------------------------------------------------------------


@pytest.mark.parametrize("override, message", [
    ("algo.lr=.nan", "algo.lr: nan is not a finite number"),
    ("algo.lr=.inf", "algo.lr: inf is not a finite number"),
    ("learner.cpus=-.inf", "learner.cpus: -inf is not a finite number"),
    ("learner.cpus=1e999", "learner.cpus: inf is not a finite number"),
    ("run.stop_at_eval_return=.inf", "run.stop_at_eval_return: inf is not a finite number"),
    ("run.max_minutes=" + "9" * 400, "run.max_minutes: "),  # an int past float's range
])
def test_non_finite_floats_are_refused(override, message):
    assert message in _one_line_error([override])


def test_non_finite_floats_in_a_yaml_file_are_refused(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text(f"defaults: [{DATA / 'child'}]\nalgo: {{lr: .NaN}}\n")
    with pytest.raises(ConfigError, match=r"^algo\.lr: nan is not a finite number$"):
        load_config(path)


# --- 4. list elements are checked like scalars -----------------------------------------


@pytest.mark.parametrize("override, message", [
    ("algo.hidden=[1.5]", "algo.hidden[0]: expected int, got float 1.5"),
    ("algo.hidden=[64, 2.5]", "algo.hidden[1]: expected int, got float 2.5"),
    ("algo.hidden=[[1]]", "algo.hidden[0]: expected int, got list [1]"),
    ("algo.hidden=[0]", "algo.hidden[0]: 0 is out of range (must be >= 1)"),
    ("algo.hidden=[abc]", "algo.hidden[0]: expected int, got str 'abc'"),
    ("algo.hidden=64", "algo.hidden: expected list, got int 64"),
    ("algo.visit_temperatures=[1, [2], 3]", "algo.visit_temperatures[1]: expected float, got list [2]"),
    ("algo.visit_temperatures=[1, .nan, 3]", "algo.visit_temperatures[1]: nan is not a finite number"),
    ("algo.visit_temperatures=[1, -1, 3]", "algo.visit_temperatures[1]: -1.0 is out of range (must be >= 0)"),
    ("algo.temperature_env_steps=[10, 1.5]", "algo.temperature_env_steps[1]: expected int, got float 1.5"),
])
def test_list_elements_are_checked_like_scalars(override, message):
    assert message in _one_line_error([override], MUZERO)


def test_integral_float_elements_become_ints():
    cfg = load_config(MUZERO, ["algo.hidden=[64, 32.0, 1e1]"])
    assert cfg.algo.hidden == [64, 32, 10] and all(type(w) is int for w in cfg.algo.hidden)


@dataclass
class _Tuples:
    widths: tuple[int, ...] = param((8,), "any number of widths", ge=1)
    pair: tuple[int, str] = param((1, "a"), "an int and a name")
    anything: list = param([], "untyped elements")


def test_tuple_types_check_each_position():
    obj = build(_Tuples, {"widths": [1, 2.0, 3], "pair": [2, "b"], "anything": [[1], "x", 1.5]})
    assert obj.widths == (1, 2, 3) and obj.pair == (2, "b") and obj.anything == [[1], "x", 1.5]
    for data, message in [
        ({"widths": [1, 1.5]}, "widths[1]: expected int, got float 1.5"),
        ({"widths": [[1]]}, "widths[0]: expected int, got list [1]"),
        ({"widths": [2, 0]}, "widths[1]: 0 is out of range (must be >= 1)"),
        ({"pair": ["a", 2]}, "pair[0]: expected int, got str 'a'"),
        ({"pair": [1, "a", 3]}, "pair: expected 2 items, got 3"),
        ({"pair": []}, "pair: expected 2 items, got 0"),
    ]:
        with pytest.raises(ConfigError) as err:
            build(_Tuples, data)
        assert str(err.value) == message


# --- 5. a bare dmc domain --------------------------------------------------------------


def test_bare_dmc_domain_says_the_task_is_missing(monkeypatch):
    from wmdist.envs import factory

    names = ["cartpole-balance", "cartpole-swingup", "walker-walk"]
    monkeypatch.setattr(factory, "_names", lambda family: names)
    for env_id in ("dmc:cartpole", "dmc:cartpole-"):
        with pytest.raises(ValueError) as err:
            factory.check_id(env_id)
        assert str(err.value) == ("dmc:cartpole names a domain but no task: dmc ids are dmc:<domain>-<task>, "
                                  "e.g. dmc:cartpole-balance, dmc:cartpole-swingup")
    with pytest.raises(ValueError, match=r"unknown env id 'dmc:walker-wlak' \(closest match: 'dmc:walker-walk'\)"):
        factory.check_id("dmc:walker-wlak")  # a wrong task keeps the closest-match message


def test_bare_dmc_domain_from_the_cli(capsys):
    pytest.importorskip("dm_control")
    assert main(["envs", "dmc:cartpole"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert err.startswith("wmdist: error: dmc:cartpole names a domain but no task: dmc ids are dmc:<domain>-<task>")
    assert "dmc:cartpole-balance" in err and "dmc:cartpole-swingup" in err


# --- 6. an env constructor that raises -------------------------------------------------


class _BrokenEnvError(RuntimeError):
    pass


def _broken_env(**kwargs):
    raise _BrokenEnvError("cannot open the simulator\nsecond line of detail")


@pytest.fixture
def broken_gym_id():
    import gymnasium as gym

    gym.register(id="WmdistBroken-v0", entry_point=_broken_env)
    yield "gym:WmdistBroken-v0"
    gym.registry.pop("WmdistBroken-v0", None)


def test_env_constructor_that_raises_is_one_config_error(broken_gym_id):
    from wmdist.runtime.train import env_spec_or_error

    cfg = load_config(CHILD, [f"env.id={broken_gym_id}"])
    with pytest.raises(ConfigError) as err:
        env_spec_or_error(cfg)
    assert str(err.value) == "env.id: cannot open the simulator"
    assert err.value.__cause__ is None and err.value.__suppress_context__


def test_env_error_without_a_message_names_its_type(monkeypatch):
    from wmdist.envs import factory
    from wmdist.runtime.train import env_spec_or_error

    def boom(cfg):
        raise KeyError()

    monkeypatch.setattr(factory, "env_spec", boom)
    with pytest.raises(ConfigError, match=r"^env\.id: KeyError$"):
        env_spec_or_error(load_config(CHILD))


def test_train_with_a_broken_env_prints_one_line(broken_gym_id, tmp_path, capsys):
    code = main(["train", CHILD, "--set", f"env.id={broken_gym_id}", f"run.dir={tmp_path}"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err == "wmdist: error: env.id: cannot open the simulator"
    assert not list(tmp_path.iterdir())  # refused before a run directory was made


# --- counts on the command line ---------------------------------------------------------


@pytest.mark.parametrize("argv", [["eval", "RUN", "--episodes", "0"], ["eval", "RUN", "--episodes", "-2"],
                                  ["dream", "RUN", "--horizon", "0"], ["dream", "RUN", "--check", "--rollouts", "0"],
                                  ["dream", "RUN", "--check", "--episodes", "0"]])
def test_counts_below_one_are_refused_before_anything_loads(argv, capsys):
    # RUN does not exist: the count must be refused by the parser, before the run is looked at
    with pytest.raises(SystemExit) as ex:
        main(argv)
    assert ex.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "must be >= 1" in err


# --- replay.pack_episodes needs a learner that restarts inside a window ------------------


def test_packed_windows_are_refused_for_muzero(tmp_path, capsys):
    code = main(["train", MUZERO, "--set", "replay.pack_episodes=true", f"run.dir={tmp_path}"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("wmdist: error: replay.pack_episodes: muzero's learner") and "\n" not in err
    assert not list(tmp_path.iterdir())


# --- values that would start a run that cannot work (session 32) ------------------------


@pytest.mark.parametrize("name", ["../../etc", "a/b", "..\\up", ".hidden", "tab\there"])
def test_run_names_with_a_path_are_refused(name):
    # `run.name=../../etc` used to create /etc-<time> from a run.dir of /tmp/x
    msg = _one_line_error([f"run.name={name}"], MUZERO)
    assert msg.startswith("run.name ") and "one folder name" in msg


@pytest.mark.parametrize("name", ["my-run", "muzero_cartpole.v2", "run 1"])
def test_ordinary_run_names_pass(name):
    assert load_config(MUZERO, [f"run.name={name}"]).run.name == name


@pytest.mark.parametrize("override, message", [
    ("replay.min_size=60001", "would wait forever"),          # capacity_steps 60,000 in the preset
    ("run.seed=99999999999999999999", "run.seed"),              # torch and numpy refuse it after start-up
    ("eval.envs=100000", "eval.envs"),
])
def test_values_a_run_cannot_serve_are_refused(override, message):
    assert message in _one_line_error([override], MUZERO)


def test_min_size_up_to_the_capacity_passes():
    assert load_config(MUZERO, ["replay.min_size=60000"]).replay.min_size == 60000


# --- values the pre-start checks used to let through (session 33) ------------------------


@pytest.mark.parametrize("sets, message", [
    (["algo.unroll_steps=60"], "algo.unroll_steps (60) must be below replay.seq_len (60)"),
    (["ray.num_gpus=4096"], "ray.num_gpus=4096, but torch sees"),  # more than any machine has: no skip on CUDA
    (["ray.object_store_mb=100000000"], "ray.object_store_mb=100000000 is more than this machine's memory"),
    # the evaluator's gpus used to be ignored (it asked Ray for its cpus only)
    (["ray.num_gpus=0", "eval.gpus=1"], "evaluator 1.0 x 1); lower actors.num or the per-role gpus"),
])
def test_what_the_machine_or_the_windows_cannot_serve_is_one_line(tmp_path, capsys, nothing_starts, sets, message):
    from tests.runtime.one_line import one_line_exit_2

    line, _ = one_line_exit_2(capsys, ["train", MUZERO, "--set", f"run.dir={tmp_path}", *sets])
    assert message in line
    assert not any(tmp_path.iterdir())


@pytest.mark.timeout(30)
def test_a_td_horizon_past_the_window_gives_the_same_targets_at_once():
    # the n-step loop ran to td_steps: 1e12 hung the learner after start-up
    import numpy as np
    from wmdist.algos.muzero.targets import make_targets

    rng = np.random.default_rng(0)
    b, t, a = 4, 12, 2
    first = np.zeros((b, t), bool)
    first[:, 0] = True
    last = np.zeros((b, t), bool)
    last[0, 7] = True
    batch = {"reward": rng.normal(size=(b, t)).astype(np.float32), "first": first, "last": last,
             "terminal": last.copy(), "mask": np.ones((b, t), bool), "action": rng.integers(0, a, (b, t)),
             "search_policy": np.full((b, t, a), 0.5, np.float32)}
    t0, valid = np.array([0, 3, 5, 1]), np.ones(b, bool)
    at_window = make_targets(batch, t0, valid, 3, t - 1, 0.97, a, np.random.default_rng(1))
    past = make_targets(batch, t0, valid, 3, 10**12, 0.97, a, np.random.default_rng(1))
    for name in ("value_partial", "boot_idx", "boot_disc", "boot_net", "value_w"):
        assert np.array_equal(getattr(at_window, name), getattr(past, name)), name
    assert (at_window.boot_idx >= 0).any() and (at_window.value_partial != 0).any()


@pytest.mark.parametrize("override", ["algo=3", "algo=[1]"])
def test_a_scalar_for_the_algo_section_is_one_line(override):
    # `--set algo=3` raised a TypeError traceback from the loader
    assert _one_line_error([override], MUZERO).startswith("algo: expected a mapping")


def test_a_binary_config_file_is_named_in_one_line(tmp_path):
    path = tmp_path / "photo.yaml"
    path.write_bytes(b"run:\n  name: x\n\xb7\xff\x00")
    msg = _one_line_error([], str(path))
    assert msg.startswith(f"{path}: not a text file")


CONFIGS = Path(__file__).parents[2] / "configs"


@pytest.mark.parametrize("preset, override", [
    ("muzero_cartpole", "algo.search.num_simulations=1000000000"),   # the tree is sized by it: an allocation after start
    ("muzero_cartpole", "eval.num_simulations=1000000000"),
    ("dreamerv3_cartpole", "algo.horizon=1000000000000"),             # an imagination that never ends
    ("planet_dmc_cartpole_swingup", "algo.planner.candidates=1000000000000"),
    ("planet_dmc_cartpole_swingup", "algo.planner.horizon=1000000000"),
    ("worldmodels_carracing", "algo.popsize=1000000000"),
    ("dreamerv3_cartpole", "algo.mlp_layers=1000000"),
])
def test_per_decision_work_and_depth_past_any_paper_are_refused(preset, override):
    key = override.split("=")[0]
    assert _one_line_error([override], str(CONFIGS / f"{preset}.yaml")).startswith(f"{key}: ")


# --- a collectors' greedy share that would do nothing ----------------------------------


@pytest.mark.parametrize("overrides, message", [
    (["algo.search.gumbel=true", "algo.greedy_fraction=0.25"], "algo.greedy_fraction has no effect with algo.search.gumbel"),
    (["algo.greedy_fraction=1.5"], "algo.greedy_fraction: 1.5 is out of range (must be <= 1)"),
])
def test_greedy_fraction_out_of_range_or_with_gumbel_is_one_line(overrides, message):
    assert message in _one_line_error(overrides, MUZERO)


# --- JEPA's per-step planning cost where it would do nothing -----------------------------

JEPA = str(Path(__file__).parents[2] / "configs" / "jepa_nav_tworooms.yaml")


@pytest.mark.parametrize("overrides, message", [
    (["algo.goal_cost=last", "algo.step_cost=0.1"], "algo.step_cost (0.1) only acts with algo.goal_cost: min"),
    (["algo.goal_cost=sum", "algo.step_cost=0.1"], "algo.step_cost (0.1) only acts with algo.goal_cost: min"),
    (["algo.step_cost=-0.1"], "algo.step_cost: -0.1 is out of range"),
])
def test_jepa_step_cost_without_the_closest_approach_cost_is_one_line(overrides, message):
    assert message in _one_line_error(overrides, JEPA)
