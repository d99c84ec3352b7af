"""`ray up` cluster files: valid against Ray's own autoscaler schema, and everything they name exists."""
from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import jsonschema
import pytest
import ray.autoscaler
import yaml
from ray.autoscaler._private.util import prepare_config, validate_config

REPO = Path(__file__).resolve().parents[2]
CLUSTER_FILES = sorted((REPO / "deploy" / "ray").glob("*.yaml"))
GUIDE = (REPO / "deploy" / "README.md").read_text()
SCHEMA = json.loads((Path(ray.autoscaler.__file__).parent / "ray-schema.json").read_text())
# Paths on a node that hold the repository: the image's /opt/wmdist, the synced ~/wmdist.
REPO_ON_NODE = re.compile(r"(?:/opt/wmdist|~/wmdist|\$HOME/wmdist)/([\w./-]+)")


def _load(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


def _commands(cfg: dict) -> list[str]:
    keys = ("initialization_commands", "setup_commands", "head_setup_commands", "worker_setup_commands",
            "head_start_ray_commands", "worker_start_ray_commands")
    cmds = [c for k in keys for c in cfg.get(k, [])]
    for nt in cfg.get("available_node_types", {}).values():
        cmds += nt.get("worker_setup_commands", []) + nt.get("initialization_commands", [])
    return cmds


def _images(cfg: dict) -> set[str]:
    d = cfg.get("docker", {})
    names = {d.get(k) for k in ("image", "head_image", "worker_image")}
    names |= {nt.get("docker", {}).get("worker_image") for nt in cfg.get("available_node_types", {}).values()}
    return {n for n in names if n}


def _dockerfile_images() -> dict[str, Path]:
    """Image name -> Dockerfile, from each Dockerfile's `ai.wmdist.image` label."""
    out = {}
    for f in (REPO / "docker").glob("*.Dockerfile"):
        for name in re.findall(r'ai\.wmdist\.image="([^"]+)"', f.read_text()):
            out[name] = f
    return out


def _make_targets() -> set[str]:
    return set(re.findall(r"^([\w-]+):", (REPO / "Makefile").read_text(), re.M))


def test_there_is_a_cloud_and_an_on_premise_cluster_file():
    providers = {_load(p)["provider"]["type"] for p in CLUSTER_FILES}
    assert {"aws", "local"} <= providers
    onprem = next(_load(p) for p in CLUSTER_FILES if _load(p)["provider"]["type"] == "local")
    assert onprem["provider"]["head_ip"] and onprem["provider"]["worker_ips"]


@pytest.mark.parametrize("path", CLUSTER_FILES, ids=lambda p: p.name)
def test_cluster_file_validates_against_the_autoscaler_schema(path):
    cfg = _load(path)
    jsonschema.validate(cfg, SCHEMA)
    # What `ray up` does before launching: merge provider defaults, then validate again.
    validate_config(prepare_config(copy.deepcopy(cfg)))


def test_a_broken_cluster_file_is_rejected_by_the_same_check():
    cfg = _load(next(p for p in CLUSTER_FILES if p.name == "aws.yaml"))
    cfg["available_node_types"]["cpu_worker"]["resources"]["collector"] = -1
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(cfg, SCHEMA)


@pytest.mark.parametrize("path", CLUSTER_FILES, ids=lambda p: p.name)
def test_everything_the_cluster_file_names_exists_in_the_repo(path):
    cfg = _load(path)
    built = _dockerfile_images()
    for image in _images(cfg):
        assert image.rsplit("/", 1)[-1] in built, f"{path.name}: image {image} is built by no docker/*.Dockerfile"
    for remote, local in cfg.get("file_mounts", {}).items():
        if local.startswith("~"):  # a file of the user's (the Ray token): the guide says how to make it
            assert local.startswith("~/.ray/auth_token") and "ray get-auth-token --generate" in GUIDE, local
            continue
        assert (REPO / local).exists(), f"{path.name}: file mount source {local} missing"
    text = " ; ".join(_commands(cfg))
    for target in re.findall(r"\bmake\b[^;&|]*", text):
        for word in target.split()[1:]:
            if "=" not in word and not word.startswith("-"):
                assert word in _make_targets(), f"{path.name}: make target {word!r} not in the Makefile"
    for rel in REPO_ON_NODE.findall(text):
        if rel.startswith(".venv/"):
            continue  # created on the node by `make setup`
        assert (REPO / rel).exists(), f"{path.name}: {rel} not in the repo"
    # Every node installs wmdist the README's way: an image built with `make setup`, or `make setup` itself.
    installs_by_make = bool(re.search(r"\bmake\b.*\bsetup\b", text))
    assert installs_by_make or _images(cfg), path.name
    # Metrics export on, on the head and the workers.
    assert "--metrics-export-port" in " ".join(cfg["head_start_ray_commands"])
    assert "--metrics-export-port" in " ".join(cfg["worker_start_ray_commands"])


def test_roles_can_be_placed_by_custom_resources():
    aws = _load(next(p for p in CLUSTER_FILES if p.name == "aws.yaml"))
    types = aws["available_node_types"]
    assert types["cpu_worker"]["resources"]["collector"] > 0 and types["cpu_worker"]["resources"]["reanalyzer"] > 0
    assert types["gpu_learner"]["resources"]["GPU"] == 1 and types["gpu_learner"]["resources"]["learner"] == 1
    local = _load(next(p for p in CLUSTER_FILES if p.name == "local.yaml"))
    workers = " ".join(local["worker_start_ray_commands"])
    m = re.search(r"--resources='([^']+)'", workers)
    assert m and json.loads(m.group(1))["collector"] > 0


def _custom_resources(cfg: dict) -> set[str]:
    """Custom resource names a cluster file offers (node types and `ray start --resources`)."""
    names = {k for t in cfg.get("available_node_types", {}).values() for k in t.get("resources", {})}
    for cmd in cfg.get("head_start_ray_commands", []) + cfg.get("worker_start_ray_commands", []):
        for m in re.finditer(r"--resources='([^']+)'", cmd):
            names |= set(json.loads(m.group(1)))
    return names - {"CPU", "GPU", "memory", "object_store_memory"}


@pytest.mark.parametrize("path", CLUSTER_FILES, ids=lambda p: p.name)
def test_every_custom_resource_is_a_role_a_config_can_place(path):
    """The cluster files read the table of roles: each custom resource they offer names a role
    whose config section has a `resources` field, and setting it asks Ray for that resource."""
    from wmdist.config.loader import load_config
    from wmdist.runtime.resources import roles
    from wmdist.runtime.table import BUILTIN

    offered = _custom_resources(_load(path))
    assert offered, path.name
    sections = {"collector": "actors", "learner": "learner", "reanalyzer": "reanalyze", "replay": "replay",
                "evaluator": "eval"}
    table = {r.name: r for r in BUILTIN}
    for name in offered:
        assert name in table, f"{path.name} offers {name!r}, which is no role of the table"
        section = sections[name]
        cfg = load_config(str(REPO / "configs" / "muzero_cartpole.yaml"),
                          [f"{section}.resources={{{name}: 1}}", "reanalyze.num=1"])
        res, _ = roles(cfg)[name]
        assert res.custom == {name: 1}, (name, res)


@pytest.mark.parametrize("dockerfile", sorted((REPO / "docker").glob("*.Dockerfile")), ids=lambda p: p.name)
def test_dockerfiles_install_through_make_setup_and_copy_only_what_exists(dockerfile):
    text = dockerfile.read_text()
    assert re.search(r"^RUN make .*\bsetup\b", text, re.M), "install through the Makefile's setup target"
    for word in re.search(r"^RUN make (.*)$", text, re.M).group(1).split():
        if "=" not in word and word not in ("&&", "\\"):
            assert word in _make_targets(), word
    for src in re.findall(r"^COPY (\S+) ", text, re.M):
        assert (REPO / src).exists(), src
    assert (dockerfile.parent / (dockerfile.name + ".dockerignore")).is_file()
    assert "ENV PATH=/opt/wmdist/.venv/bin" in text  # `ray` and `wmdist` on PATH for ray up


def test_the_guide_walks_through_launch_submit_scale_watch_and_teardown():
    for step in ("ray up deploy/ray/aws.yaml", "ray up deploy/ray/local.yaml", "ray job submit", "--address auto",
                 "actors.num=", "replay.shards=", "resources: {collector: 1}", "wmdist monitor", "ray down"):
        assert step in GUIDE, step
    for rel in set(re.findall(r"\b((?:deploy|docker)/[\w./-]+\.(?:yaml|yml|Dockerfile|json))\b", GUIDE)):
        assert (REPO / rel).exists(), rel
