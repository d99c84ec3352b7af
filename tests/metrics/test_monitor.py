"""`monitor_commands`: a valid Prometheus config in the run dir and loopback launch commands."""
from __future__ import annotations

import shutil
import subprocess

import pytest
import yaml

from wmdist.telemetry.monitor import monitor_commands, render_prometheus_config


def test_monitor_writes_a_valid_config_and_prints_loopback_commands(tmp_path):
    text = monitor_commands(str(tmp_path), 45678, prometheus_port=9191, grafana_port=3100)
    config = tmp_path / "monitor" / "prometheus.yml"
    cfg = yaml.safe_load(config.read_text())
    jobs = {j["job_name"]: j for j in cfg["scrape_configs"]}
    assert jobs["wmdist"]["static_configs"] == [{"targets": ["127.0.0.1:45678"]}]
    assert jobs["ray"]["file_sd_configs"][0]["files"][0].endswith("prom_metrics_service_discovery.json")
    assert (tmp_path / "monitor" / "alerts.yml").is_file()
    check = subprocess.run([shutil.which("promtool"), "check", "config", str(config)], capture_output=True, text=True)
    assert check.returncode == 0, check.stdout + check.stderr
    assert "SUCCESS: 4 rules found" in check.stdout + check.stderr
    assert f"--config.file={config}" in text and "--web.listen-address=127.0.0.1:9191" in text
    assert "WMDIST_PROMETHEUS_URL=http://127.0.0.1:9191" in text and "GF_SERVER_HTTP_PORT=3100" in text
    assert "GF_SERVER_HTTP_ADDR=127.0.0.1" in text and "grafana server" in text and "docker run" in text
    assert "0.0.0.0" not in text


def test_scrape_interval_override_and_bad_input():
    cfg = yaml.safe_load(render_prometheus_config("127.0.0.1:1", ray_sd_path="/x.json", scrape_interval="1s"))
    assert {j["scrape_interval"] for j in cfg["scrape_configs"]} == {"1s"} and cfg["global"]["scrape_interval"] == "1s"
    with pytest.raises(ValueError, match="host:port"):
        render_prometheus_config("localhost")
    with pytest.raises(ValueError, match="metrics_port"):
        monitor_commands("/", 0)
    with pytest.raises(ValueError, match="does not exist"):
        monitor_commands("/no/such/run", 9000)
