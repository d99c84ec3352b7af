"""Prometheus and Grafana beside a local run: config files and the commands to start them.

`monitor_commands(run_dir, metrics_port)` writes `RUN_DIR/monitor/prometheus.yml` (the
template `deploy/prometheus/prometheus.yml` pointed at this run's exporter and the local
Ray node's discovery file) plus the alert rules next to it, and returns the shell commands
that start Prometheus and Grafana (provisioned from `deploy/grafana/`), all on loopback.
"""
from __future__ import annotations

import os
import shlex
import shutil
import tempfile
from pathlib import Path
from typing import Any

import yaml

RAY_SD_FILENAME = "prom_metrics_service_discovery.json"  # written by Ray's dashboard head


def deploy_dir() -> Path:
    """The repository's `deploy/` folder (wmdist is installed editable, as `make setup` does)."""
    d = Path(__file__).resolve().parents[2] / "deploy"
    if not (d / "prometheus" / "prometheus.yml").is_file():
        raise ValueError(f"deploy/ templates not found at {d}: install wmdist from its repository (make setup)")
    return d


def ray_sd_file() -> str:
    """Where a local Ray writes its Prometheus file-SD list (Ray's temp dir, /tmp/ray by default)."""
    root = os.environ.get("RAY_TMPDIR") or tempfile.gettempdir()
    return os.path.join(root, "ray", RAY_SD_FILENAME)


def _check_port(name: str, port: int, allow_zero: bool = False) -> int:
    lo = 0 if allow_zero else 1
    if isinstance(port, bool) or not isinstance(port, int) or not lo <= port <= 65535:
        raise ValueError(f"{name} must be an integer port in [{lo}, 65535], got {port!r}")
    return port


def render_prometheus_config(
    metrics_target: str,
    *,
    ray_sd_path: str | None = None,
    scrape_interval: str | None = None,
) -> str:
    """The project's scrape config (YAML text) with the wmdist job pointed at `metrics_target`.

    metrics_target: `host:port` of the wmdist exporter. ray_sd_path: Ray's file-SD list
    (default: the local Ray's). scrape_interval: override every interval (e.g. "1s" in tests).
    """
    if ":" not in metrics_target:
        raise ValueError(f"metrics_target must be host:port, got {metrics_target!r}")
    cfg: dict[str, Any] = yaml.safe_load((deploy_dir() / "prometheus" / "prometheus.yml").read_text())
    jobs = {j["job_name"]: j for j in cfg["scrape_configs"]}
    jobs["wmdist"]["static_configs"] = [{"targets": [metrics_target]}]
    jobs["ray"]["file_sd_configs"] = [{"files": [ray_sd_path or ray_sd_file()]}]
    if scrape_interval is not None:
        cfg["global"]["scrape_interval"] = cfg["global"]["evaluation_interval"] = scrape_interval
        for j in jobs.values():
            j["scrape_interval"] = scrape_interval
    header = "# Written by wmdist from deploy/prometheus/prometheus.yml; edit the template, not this copy.\n"
    return header + yaml.safe_dump(cfg, sort_keys=False)


def write_prometheus_config(out_dir: str | os.PathLike[str], metrics_port: int, **kw: Any) -> Path:
    """Write `prometheus.yml` and the alert rules it names into `out_dir`; returns the config path."""
    _check_port("metrics_port", metrics_port)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "prometheus.yml"
    path.write_text(render_prometheus_config(f"127.0.0.1:{metrics_port}", **kw))
    shutil.copyfile(deploy_dir() / "prometheus" / "alerts.yml", out / "alerts.yml")
    return path


def tensorboard_lines(run: Path) -> list[str]:
    """How to open the run's TensorBoard event files (none if it wrote none)."""
    from wmdist.telemetry.tensorboard import TB_DIR

    if not (run / TB_DIR).is_dir():
        return ["# TensorBoard: this run wrote no event files (metrics.tensorboard: false)"]
    return ["# TensorBoard: every metrics.jsonl scalar, the learning curve (Images). UI: http://127.0.0.1:6006",
            f"tensorboard --logdir {shlex.quote(str(run / TB_DIR))} --host 127.0.0.1 --port 6006"]


def monitor_commands(
    run_dir: str,
    metrics_port: int,
    *,
    prometheus_port: int = 9090,
    grafana_port: int = 3000,
) -> str:
    """Write the run's Prometheus config and return the commands to launch Prometheus and Grafana."""
    _check_port("prometheus_port", prometheus_port)
    _check_port("grafana_port", grafana_port)
    run = Path(run_dir).resolve()
    if not run.is_dir():
        raise ValueError(f"run directory {run_dir!r} does not exist")
    mon = run / "monitor"
    config = write_prometheus_config(mon, metrics_port)
    grafana = deploy_dir() / "grafana"
    q = lambda p: shlex.quote(str(p))  # noqa: E731
    prom_url = f"http://127.0.0.1:{prometheus_port}"
    env = {
        "WMDIST_PROMETHEUS_URL": prom_url,
        "GF_SERVER_HTTP_ADDR": "127.0.0.1",
        "GF_SERVER_HTTP_PORT": str(grafana_port),
        "GF_AUTH_ANONYMOUS_ENABLED": "true",  # loopback only: a read-only viewer without login
        "GF_AUTH_ANONYMOUS_ORG_ROLE": "Viewer",
    }
    local_env = {
        **env,
        "WMDIST_DASHBOARDS_DIR": str(grafana / "dashboards"),
        "GF_PATHS_PROVISIONING": str(grafana / "provisioning"),
        "GF_PATHS_DATA": str(mon / "grafana-data"),
    }
    docker_env = {**env, "WMDIST_DASHBOARDS_DIR": "/etc/grafana/dashboards/wmdist"}
    lines = [*tensorboard_lines(run), "",
        f"# Prometheus: scrapes the wmdist exporter (127.0.0.1:{metrics_port}) and the local Ray node;",
        f"# alert rules from deploy/prometheus/alerts.yml. UI: {prom_url}",
        f"prometheus --config.file={q(config)} --storage.tsdb.path={q(mon / 'prometheus-data')} "
        f"--web.listen-address=127.0.0.1:{prometheus_port}",
        "",
        f"# Grafana: dashboard 'wmdist training' at http://127.0.0.1:{grafana_port} (anonymous read-only on loopback).",
        " ".join(f"{k}={q(v)}" for k, v in local_env.items()) + " grafana server --homepath /usr/share/grafana",
        "",
        "# ... or Grafana from its container image (host network, same loopback ports):",
        "docker run --rm --network host "
        + " ".join(f"-e {k}={q(v)}" for k, v in docker_env.items())
        + f" -v {q(grafana / 'provisioning')}:/etc/grafana/provisioning:ro"
        + f" -v {q(grafana / 'dashboards')}:/etc/grafana/dashboards/wmdist:ro grafana/grafana",
    ]
    return "\n".join(lines) + "\n"
