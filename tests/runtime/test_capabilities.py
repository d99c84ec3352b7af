"""The runtime asks an algorithm what it can do (`Algorithm.offers`), never what it is called.

Capabilities are declared in `wmdist/algos/base.py`; a command that needs one (`wmdist dream`
needs PREDICTS_OBSERVATIONS) refuses other algorithms in one line, exit status 2.
"""
from __future__ import annotations

import ast
import io
from pathlib import Path

import pytest

from wmdist.algos.base import (CAPABILITIES, CHECKS_DREAM, MEASURES_PREDICTION, PACKED_WINDOWS, PLANS, PLOTS_EMBEDDINGS,
                               PREDICTS_OBSERVATIONS, REANALYZE, TWO_PLAYER, Algorithm)
from wmdist.algos.registry import ALGORITHMS, resolve
from wmdist.cli import main
from tests.runtime.run_dirs import run_dir_with_checkpoint

ROOT = Path(__file__).resolve().parents[2]
# the code that must stay algorithm-agnostic
AGNOSTIC = [ROOT / "wmdist" / "runtime", ROOT / "wmdist" / "telemetry", ROOT / "wmdist" / "cli.py", ROOT / "wmdist" / "config"]


# --- 1. no branching on an algorithm's name ------------------------------------------------

def _is_name_ref(node: ast.AST) -> bool:
    """`algo_name`, `x.algo_name`, `algo.name`, `cfg.algo.name`, `type(a).name`-like references."""
    if isinstance(node, ast.Name):
        return node.id == "algo_name"
    if isinstance(node, ast.Attribute):
        if node.attr == "algo_name":
            return True
        return node.attr == "name" and isinstance(node.value, (ast.Name, ast.Attribute)) and \
            (getattr(node.value, "id", None) or getattr(node.value, "attr", None)) in ("algo", "algorithm")
    return False


def _literal_strings(node: ast.AST) -> list[str]:
    """The string constants of a literal, or of a tuple/list/set/dict literal of them."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [s for e in node.elts for s in _literal_strings(e)]
    if isinstance(node, ast.Dict):
        return [s for k in node.keys if k is not None for s in _literal_strings(k)]
    return []


def name_branches(source: str, names: set[str]) -> list[str]:
    """Every place `source` compares or dispatches on an algorithm's name: a comparison or `in`
    test against a registered name, an `algo_name`-like value against a string literal, a
    `match` on one, or a dict literal keyed by registered names. Comparing two algo names
    (a resume keeps its algorithm) and names inside messages are fine."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            literals = [s for o in operands for s in _literal_strings(o)]
            if set(literals) & names or (any(map(_is_name_ref, operands)) and literals):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Match) and _is_name_ref(node.subject):
            found.append(f"line {node.lineno}: match {ast.unparse(node.subject)}")
        elif isinstance(node, ast.Dict) and set(_literal_strings(node)) & names:
            found.append(f"line {node.lineno}: dict keyed by algorithm names")
    return found


def _sources() -> list[Path]:
    files = []
    for p in AGNOSTIC:
        files += sorted(p.rglob("*.py")) if p.is_dir() else [p]
    return files


def test_the_checker_catches_the_old_dream_check():
    names = set(ALGORITHMS)
    old = 'if cfg.algo_name != "dreamer":\n    raise ConfigError(f"dream shows a Dreamer world model")\n'
    assert name_branches(old, names)
    assert name_branches('x = 1 if algo.name in ("muzero", "other") else 2\n', names)
    assert name_branches('match cfg.algo_name:\n    case "x":\n        pass\n', names)
    assert name_branches('LOSS = {"dreamer": "model_loss", "muzero": "loss"}\n', names)
    # fine: a message naming the algorithm, and a resume check that the algorithm is unchanged
    assert not name_branches('raise ValueError(f"{cfg.algo_name!r} has no reanalyze step; muzero has")\n', names)
    assert not name_branches("if saved.algo_name != cfg.algo_name:\n    pass\n", names)
    assert not name_branches('if "algo_name" in tree:\n    pass\n', names)


def test_runtime_cli_and_config_never_branch_on_an_algorithm_name():
    names = set(ALGORITHMS)
    assert names, "no registered algorithms"
    files = _sources()
    assert len(files) > 10, files
    offences = []
    for path in files:
        offences += [f"{path.relative_to(ROOT)} {hit}" for hit in name_branches(path.read_text(), names)]
    assert not offences, "use Algorithm.offers(<capability>) instead:\n" + "\n".join(offences)


# --- 2. declared capabilities --------------------------------------------------------------

def test_capability_constants_are_the_known_set():
    assert CAPABILITIES == {PREDICTS_OBSERVATIONS, TWO_PLAYER, REANALYZE, PLANS, PLOTS_EMBEDDINGS, PACKED_WINDOWS,
                            CHECKS_DREAM, MEASURES_PREDICTION}
    assert all(isinstance(c, str) for c in CAPABILITIES)
    assert Algorithm.capabilities == frozenset()
    with pytest.raises(ValueError, match="unknown capability"):
        Algorithm.offers("predicts_obs")  # a typo is an error, not a silent False


@pytest.mark.parametrize("name", sorted(ALGORITHMS))
def test_registered_algorithms_declare_only_known_capabilities(name):
    cls = resolve(name)
    assert isinstance(cls.capabilities, frozenset)
    assert cls.capabilities <= CAPABILITIES, cls.capabilities - CAPABILITIES
    # the declarations agree with the methods behind them
    assert cls.offers(REANALYZE) == (cls.make_reanalyzer is not Algorithm.make_reanalyzer)
    assert cls.offers(PREDICTS_OBSERVATIONS) == (cls.dream_video is not Algorithm.dream_video)
    assert cls.offers(PLOTS_EMBEDDINGS) == (cls.embedding_plot is not Algorithm.embedding_plot)


def test_dreamer_predicts_observations_and_muzero_plans():
    dreamer, muzero = resolve("dreamer"), resolve("muzero")
    assert dreamer.offers(PREDICTS_OBSERVATIONS)
    assert not dreamer.offers(PLANS) and not dreamer.offers(REANALYZE) and not dreamer.offers(TWO_PLAYER)
    assert not muzero.offers(PREDICTS_OBSERVATIONS)
    assert muzero.offers(PLANS) and muzero.offers(REANALYZE) and muzero.offers(TWO_PLAYER)


def test_default_dream_video_is_not_implemented():
    from wmdist.envs.config import EnvConfig
    from wmdist.envs.factory import env_spec

    muzero = resolve("muzero")(env_spec(EnvConfig(id="gym:CartPole-v1")), None, 0)
    with pytest.raises(NotImplementedError):
        muzero.dream_video({}, None, "x.gif")


# --- 3. `wmdist dream` asks for the capability ---------------------------------------------

def test_dream_on_a_muzero_run_is_one_line_exit_2(tmp_path, capsys):
    run_dir = run_dir_with_checkpoint(tmp_path, "muzero_cartpole")
    assert main(["dream", str(run_dir)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wmdist: error: "), captured.err
    assert "predicts observations" in lines[0] and "'muzero'" in lines[0]
    assert "Traceback" not in captured.out + captured.err
    assert not (run_dir / "dream.gif").exists()
    assert main(["dream", str(run_dir), "--check"]) == 2  # World Models' dream check, likewise
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "dream" in lines[0] and "'muzero'" in lines[0]
    assert not (run_dir / "dream_check.json").exists()


def test_dream_on_a_dreamer_run_writes_the_video(tmp_path, capsys):
    tiny = ["algo.deter=32", "algo.units=32", "algo.mlp_layers=1", "algo.stoch=4", "algo.classes=4"]
    run_dir = run_dir_with_checkpoint(tmp_path, "dreamerv3_cartpole", tiny)
    assert main(["dream", str(run_dir), "--horizon", "5"]) == 0
    out = capsys.readouterr().out
    assert "dream video" in out
    assert (run_dir / "dream.gif").stat().st_size > 0


def test_dream_of_an_embedding_model_is_its_trajectory_plot(tmp_path):
    """No decoder (JEPA): `wmdist dream` draws the planned embedding trajectory instead of a video."""
    from wmdist.runtime.evaluate import dream_run

    from wmdist.config.errors import ConfigError
    from wmdist.config.loader import dump_yaml, load_config
    from wmdist.runtime.checkpoint import save_checkpoint
    from wmdist.runtime.local import LocalSession

    untrained = run_dir_with_checkpoint(tmp_path / "untrained", "jepa_nav_tworooms")
    with pytest.raises(ConfigError, match="before any training"):  # one line, not a traceback
        dream_run(str(untrained), horizon=3, stream=io.StringIO())
    cfg = load_config(str(Path(__file__).parents[2] / "configs" / "jepa_nav_tworooms.yaml"),
                      [f"run.dir={tmp_path}", "ray.local=true", "actors.num=1", "actors.envs_per_actor=2",
                       "actors.segment_steps=8", "learner.batch_size=4"])
    session = LocalSession(cfg)
    try:  # a few real updates on data the runtime's collector gathered
        session.collect(3)
        session.train(2, 4)
        run = tmp_path / "trained"
        run.mkdir()
        (run / "config.yaml").write_text(dump_yaml(cfg))
        save_checkpoint(run, {"learner": session.learner.state_dict()}, session.learner.get_weights(), 1,
                        {"updates": 2, "env_steps": session.env_steps}, None, keep=1)
    finally:
        session.close()
    out = io.StringIO()
    assert dream_run(str(run), horizon=3, stream=out) == 0
    assert "embedding plot" in out.getvalue() and (run / "dream.png").stat().st_size > 1000
