"""Static checks of deploy/prometheus and deploy/grafana: promtool, rule unit tests, dashboard shape."""
from __future__ import annotations

import json
import re

import yaml

from tests.deploy.prom import DEPLOY, alert_rules, dashboard_queries, promtool
from wmdist.telemetry.metrics import METRICS

PROM = DEPLOY / "prometheus"


def test_promtool_checks_the_scrape_config_and_the_rules():
    cfg = promtool("check", "config", str(PROM / "prometheus.yml"))
    assert cfg.returncode == 0, cfg.stdout + cfg.stderr
    rules = promtool("check", "rules", str(PROM / "alerts.yml"))
    assert rules.returncode == 0 and "SUCCESS: 4 rules found" in rules.stdout, rules.stdout + rules.stderr
    doc = yaml.safe_load((PROM / "prometheus.yml").read_text())
    jobs = {j["job_name"]: j for j in doc["scrape_configs"]}
    assert jobs["ray"]["file_sd_configs"][0]["files"] == ["/tmp/ray/prom_metrics_service_discovery.json"]
    assert jobs["wmdist"]["static_configs"][0]["targets"][0].startswith("127.0.0.1:")


def test_promtool_rejects_a_broken_rule(tmp_path):
    bad = tmp_path / "bad.yml"
    bad.write_text("groups:\n- name: x\n  rules:\n  - alert: A\n    expr: rate(wmdist_env_steps_total[5m] == 0\n")
    assert promtool("check", "rules", str(bad)).returncode != 0


def test_alert_rules_fire_on_the_failures_they_name_and_not_before():
    """promtool's rule unit tests: stalled env steps, a growing version gap, rising NaN skips."""
    res = promtool("test", "rules", "alerts_test.yml", cwd=PROM)
    assert res.returncode == 0, res.stdout + res.stderr
    tested = set(re.findall(r"alertname: (\w+)", (PROM / "alerts_test.yml").read_text()))
    assert tested == {name for name, _ in alert_rules()}
    assert {"WmdistEnvStepsStalled", "WmdistWeightVersionGapHigh", "WmdistNanSkipsRising"} <= tested


def test_dashboard_and_rules_use_only_declared_metrics_and_cover_them_all():
    exprs = [e for _, e in dashboard_queries()] + [e for _, e in alert_rules()]
    used = {m for e in exprs for m in re.findall(r"\bwmdist_\w+", e)}
    assert used <= set(METRICS), used - set(METRICS)
    assert set(METRICS) <= used, f"metrics no panel shows: {set(METRICS) - used}"
    ray_used = {m for e in exprs for m in re.findall(r"\bray_\w+", e)}
    assert {"ray_node_cpu_utilization", "ray_node_mem_used"} <= ray_used


def test_dashboard_panels_point_at_the_provisioned_datasource():
    ds = yaml.safe_load((DEPLOY / "grafana" / "provisioning" / "datasources" / "wmdist.yaml").read_text())
    uid = ds["datasources"][0]["uid"]
    providers = yaml.safe_load((DEPLOY / "grafana" / "provisioning" / "dashboards" / "wmdist.yaml").read_text())
    assert providers["providers"][0]["type"] == "file"
    for path in (DEPLOY / "grafana" / "dashboards").glob("*.json"):
        dash = json.loads(path.read_text())
        ids = [p["id"] for p in dash["panels"]]
        assert len(ids) == len(set(ids)) and dash["uid"]
        for p in dash["panels"]:
            assert {"x", "y", "w", "h"} <= set(p["gridPos"]), p["title"]
            if p["type"] != "row":
                assert p["datasource"]["uid"] == uid and p["targets"], p["title"]
                assert all(t["datasource"]["uid"] == uid and t["expr"].strip() for t in p["targets"]), p["title"]
    titles = " ".join(t for t, _ in dashboard_queries()).lower()
    for must in ("env steps per second", "updates per second", "episode return", "losses", "replay size",
                 "inserts", "samples", "drops", "limiter", "version gap", "restarts", "cpu per node", "memory per node"):
        assert must in titles, must
