"""Load a run config: YAML defaults/overlays, then `--set a.b=value` overrides, then a typed
check of every key, type and range. Every problem is one `ConfigError` line."""
from __future__ import annotations

import dataclasses
import math
import os
import re
import types
import typing
from pathlib import Path
from typing import Any, Union

import yaml

from wmdist.config.errors import ConfigError, closest
from wmdist.config.schema import RunConfig

MAX_DEFAULTS_DEPTH = 8
# The shipped presets (`base`, `muzero_cartpole`, ...): a config copied out of the project's
# `configs/` keeps its `defaults:` working, since names not found beside the file are looked up here.
PRESETS_DIR = Path(__file__).resolve().parents[2] / "configs"

_FLOAT_TAG = "tag:yaml.org,2002:float"
# PyYAML's YAML 1.1 float needs a dot and a signed exponent (`1.0e-4`), so `1e-4`, `3e5` and
# `-.5` would load as strings; this is its pattern with those forms added (ints stay ints).
_FLOAT = re.compile(r"""^(?:[-+]?[0-9][0-9_]*\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+
    |[-+]?\.[0-9][0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""", re.X)


class _Loader(yaml.SafeLoader):
    """SafeLoader that reads numbers as people write them (see `_FLOAT`)."""


_Loader.yaml_implicit_resolvers = {
    first: [(tag, _FLOAT if tag == _FLOAT_TAG else regexp) for tag, regexp in resolvers]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}


def parse_yaml(text: str) -> Any:
    """`yaml.safe_load` that also reads `1e-4`, `3e5`, `1E+3` and `.5` as floats."""
    return yaml.load(text, Loader=_Loader)


def read_yaml_mapping(path: Path) -> dict:
    """A YAML file's top-level mapping; a missing file, bad YAML or another top level is one ConfigError line."""
    if path.is_dir():
        if (path / "config.yaml").is_file():  # a run directory given where a config goes
            raise ConfigError(f"{path} is a run directory, not a config file; continue it with "
                              f"`wmdist train --resume {path}`")
        inside = sorted(p.name for p in path.glob("*.yaml"))[:3]
        raise ConfigError(f"{path} is a directory, not a config file"
                          + (f" (it holds {', '.join(inside)}, ...)" if inside else ""))
    if not path.is_file():
        raise ConfigError(f"config file not found: {path}")
    try:
        data = parse_yaml(path.read_text()) or {}
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not a text file (byte {err.start} is not UTF-8)") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{path}:{where} is not valid YAML: {getattr(err, 'problem', err)}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: top level must be a mapping, got {type(data).__name__}")
    return data


def _merge(base: dict, over: dict) -> dict:
    """Deep merge: mappings merge key by key, anything else replaces."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _find_default(path: Path, name: Any) -> Path:
    """The file a `defaults:` entry of `path` names: beside it, else among the shipped presets."""
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{path}: defaults entries are config names (e.g. base), got {name!r}")
    file = name if name.endswith((".yaml", ".yml")) else f"{name}.yaml"
    for folder in (path.parent, PRESETS_DIR):
        if (folder / file).is_file():
            return folder / file
    raise ConfigError(f"{path}: defaults entry {name!r} names no config: no {file} beside it"
                      + (f" or among the presets in {PRESETS_DIR}" if PRESETS_DIR.is_dir() else ""))


def load_yaml_tree(path: str | os.PathLike, depth: int = 0) -> dict:
    """A file with its `defaults: [name, ...]` overlays merged underneath (each found beside the
    file, else among the shipped presets)."""
    path = Path(path)
    if depth > MAX_DEFAULTS_DEPTH:
        raise ConfigError(f"{path}: defaults nest deeper than {MAX_DEFAULTS_DEPTH} (a cycle?)")
    data = read_yaml_mapping(path)
    defaults = data.pop("defaults", []) or []
    if isinstance(defaults, str):
        defaults = [defaults]
    if not isinstance(defaults, list):
        raise ConfigError(f"{path}: defaults must be a list of config names, got {type(defaults).__name__}")
    merged: dict = {}
    for name in defaults:
        merged = _merge(merged, load_yaml_tree(_find_default(path, name), depth + 1))
    return _merge(merged, data)


def apply_overrides(tree: dict, overrides: list[str]) -> dict:
    """`a.b.c=value` pairs (value parsed as YAML) applied in order, last one wins."""
    tree = dict(tree)
    for item in overrides:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"override {item!r} is not of the form key.path=value")
        try:
            value = parse_yaml(raw) if raw.strip() else ""
        except yaml.YAMLError:
            value = raw
        parts = key.strip().split(".")
        node = tree
        for p in parts[:-1]:
            nxt = node.get(p)
            nxt = dict(nxt) if isinstance(nxt, dict) else {}
            node[p] = nxt
            node = nxt
        node[parts[-1]] = value
    return tree


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp).replace("typing.", ""))


def _convert(value: Any, tp: Any, key: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(value, arg, key)
            except ConfigError as err:
                errors.append(str(err))
        raise ConfigError(errors[0] if errors else f"{key}: bad value {value!r}")
    if tp is Any:
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{key}: expected a mapping of {tp.__name__} fields, got {value!r}")
        return build(tp, value, key)
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
    elif tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            try:
                number = float(value)
            except OverflowError:  # an int past float's range
                number = math.inf
            if not math.isfinite(number):  # `.nan`/`.inf` pass every range check, then train garbage
                raise ConfigError(f"{key}: {value!r} is not a finite number")
            return number
    elif tp is str:
        if isinstance(value, str):
            return value
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return str(value)
    elif origin in (list, tuple) or tp in (list, tuple):
        if isinstance(value, (list, tuple)):
            item_types = _item_types(tp, len(value), key)
            items = [_convert(v, t, f"{key}[{i}]") for i, (v, t) in enumerate(zip(value, item_types))]
            return tuple(items) if (origin or tp) is tuple else items
    elif origin is dict or tp is dict:
        if isinstance(value, dict):
            return dict(value)
    else:
        return value
    raise ConfigError(f"{key}: expected {_type_name(tp)}, got {type(value).__name__} {value!r}")


def _item_types(tp: Any, length: int, key: str) -> list:
    """The element types of a `length`-item value of `list[T]`, `tuple[T, ...]`, `tuple[A, B]`, `list`."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) is tuple and args and not (len(args) == 2 and args[1] is Ellipsis):
        if length != len(args):  # a fixed-length tuple: one value per declared type
            raise ConfigError(f"{key}: expected {len(args)} items, got {length}")
        return list(args)
    return [args[0] if args else Any] * length


def _check_range(value: Any, meta: dict, key: str) -> None:
    if isinstance(value, (list, tuple)):  # a list of widths/steps: each element has the field's range
        for i, item in enumerate(value):
            _check_range(item, meta, f"{key}[{i}]")
        return
    if value is None or isinstance(value, bool):
        return
    choices = meta.get("choices")
    if choices is not None and value not in choices:
        raise ConfigError(f"{key}: {value!r} is not one of {', '.join(map(repr, choices))}")
    if not isinstance(value, (int, float)):
        return
    for name, bad, word in (("ge", lambda v, b: v < b, ">="), ("gt", lambda v, b: v <= b, ">"),
                            ("le", lambda v, b: v > b, "<="), ("lt", lambda v, b: v >= b, "<")):
        bound = meta.get(name)
        if bound is not None and bad(value, bound):
            raise ConfigError(f"{key}: {value!r} is out of range (must be {word} {bound})")


def build(cls: type, data: dict, prefix: str = "") -> Any:
    """A dataclass instance from a mapping, checking every key, type and range."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in data.items():
        full = f"{prefix}.{key}" if prefix else str(key)
        if key not in fields:
            raise ConfigError(f"unknown key '{full}'{_suggest(prefix, key, fields)}")
        value = _convert(value, hints[key], full)
        _check_range(value, dict(fields[key].metadata), full)
        kwargs[key] = value
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{prefix or 'config'}: {err}") from None
    return obj


def _suggest(prefix: str, key: str, fields: dict) -> str:
    hint = closest(key, fields)
    return hint.replace("'", f"'{prefix}.", 1) if hint and prefix else hint


def load_config(path: str | os.PathLike, overrides: list[str] | None = None) -> RunConfig:
    """The resolved, checked run config for a YAML file plus overrides."""
    tree = apply_overrides(load_yaml_tree(path), list(overrides or []))
    return config_from_tree(tree, default_name=Path(path).stem)


def config_from_tree(tree: dict, default_name: str = "run") -> RunConfig:
    from wmdist.algos.registry import resolve

    tree = dict(tree)
    if "algo_name" in tree:
        raise ConfigError("unknown key 'algo_name' (did you mean 'algo.name'?)")
    algo_tree = tree.pop("algo", None) or {}
    if not isinstance(algo_tree, dict):
        raise ConfigError(f"algo: expected a mapping of the algorithm's fields (e.g. algo: {{name: muzero}}), got {algo_tree!r}")
    algo_tree = dict(algo_tree)
    name = algo_tree.pop("name", None)
    if not name:
        raise ConfigError("algo.name is missing (e.g. algo: {name: muzero})")
    if not isinstance(name, str):
        raise ConfigError(f"algo.name: expected str, got {name!r}")
    algo_cls = resolve(name)
    cfg = build(RunConfig, tree)
    cfg.algo = build(algo_cls.Config, algo_tree, "algo")
    cfg.algo_name = name
    if not cfg.run.name:
        cfg.run.name = default_name
    check_consistency(cfg)
    return cfg


def check_consistency(cfg: RunConfig) -> None:
    """Cross-field checks that a single field's range can't express (each section's own)."""
    for section in (cfg.env, cfg.replay, cfg.algo):
        validate = getattr(section, "validate", None)
        if validate is None:
            continue
        try:
            validate()
        except ValueError as err:
            raise ConfigError(str(err).strip().splitlines()[0]) from None
    if cfg.eval.num_simulations and not hasattr(getattr(cfg.algo, "search", None), "num_simulations"):
        raise ConfigError(f"eval.num_simulations: algorithm '{cfg.algo_name}' has no tree search (leave it 0)")
    if cfg.eval.explore and cfg.env.id.startswith("board:"):
        raise ConfigError("eval.explore: board games are judged greedily against the opponent (leave it false)")
    check_run_name(cfg.run.name)


def check_run_name(name: str) -> None:
    """The run directory is <run.dir>/<name>-<time>: a name with a path in it would put the run
    (and everything it writes) outside run.dir, e.g. `../../etc`."""
    bad = [c for c in name if c in "/\\" or not c.isprintable()]
    if bad or name.startswith(".") or not name.strip():
        raise ConfigError(f"run.name {name!r}: a run name is one folder name (no '/', '\\', control characters "
                          f"or leading '.'); it names <run.dir>/<name>-<time>")


def to_dict(cfg: Any) -> Any:
    """Plain data for YAML (the algo section gets its `name` back)."""
    if isinstance(cfg, RunConfig):
        out = {f.name: to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg) if f.name != "algo_name"}
        out["algo"] = {"name": cfg.algo_name, **to_dict(cfg.algo)}
        return out
    if dataclasses.is_dataclass(cfg):
        return {f.name: to_dict(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    if isinstance(cfg, (list, tuple)):
        return [to_dict(v) for v in cfg]
    if isinstance(cfg, dict):
        return {k: to_dict(v) for k, v in cfg.items()}
    return cfg


def dump_yaml(cfg: RunConfig) -> str:
    return yaml.safe_dump(to_dict(cfg), sort_keys=False, default_flow_style=False)


def describe(cls: type, prefix: str = "") -> list[tuple[str, str, str]]:
    """(key, default, doc) for every field, for `wmdist config --docs`."""
    rows = []
    for f in dataclasses.fields(cls):
        key = f"{prefix}.{f.name}" if prefix else f.name
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)  # type: ignore[misc]
        if dataclasses.is_dataclass(default):
            rows.extend(describe(type(default), key))
        else:
            rows.append((key, repr(default), f.metadata.get("doc", "")))
    return rows
