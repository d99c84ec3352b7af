"""A real Prometheus scrapes a live wmdist exporter and a real Ray node with the project's config;
every dashboard query and every alert expression is evaluated through Prometheus' HTTP API."""
from __future__ import annotations

import json
import re
import time

from tests.deploy.prom import alert_rules, dashboard_queries, query, running_prometheus
from tests.deploy.real_run import real_run
from wmdist.telemetry.monitor import write_prometheus_config


def _ray_sd_file(ray, path) -> None:
    """Ray's file-SD list for the session's Ray node, in the format Ray's dashboard head writes.

    The session's Ray runs without the dashboard head (which is what writes this file on a
    cluster), so the test writes the same JSON from `ray.nodes()`.
    """
    targets = [f"{n['NodeManagerAddress']}:{n['MetricsExportPort']}" for n in ray.nodes() if n["Alive"]]
    assert targets
    path.write_text(json.dumps([{"labels": {"job": "ray"}, "targets": targets}]))


def test_every_dashboard_query_and_alert_expression_returns_data(ray_session, tmp_path):
    queries = dashboard_queries()
    alerts = alert_rules()
    sd = tmp_path / "prom_metrics_service_discovery.json"
    _ray_sd_file(ray_session, sd)
    with real_run(tmp_path) as source:
        config = write_prometheus_config(tmp_path / "monitor", source.port, ray_sd_path=str(sd), scrape_interval="1s")
        with running_prometheus(config, tmp_path / "tsdb") as prom:
            # Wait until every panel query has data (rates need two scrapes; Ray's agent reports every few s).
            deadline = time.monotonic() + 90
            empty = queries
            while empty and time.monotonic() < deadline:
                time.sleep(1.0)
                empty = [(t, e) for t, e in empty if not query(prom, e).get("data", {}).get("result")]
            assert not empty, f"panel queries without data: {empty}"

            for title, expr in queries:
                res = query(prom, expr)
                assert res["status"] == "success" and res["data"]["result"], (title, expr, res)

            up = query(prom, "up")["data"]["result"]
            assert {r["metric"]["job"] for r in up if r["value"][1] == "1"} == {"wmdist", "ray"}, up

            for name, expr in alerts:
                res = query(prom, expr)
                assert res["status"] == "success", (name, expr, res)  # parses and evaluates on live data
                # The series each alert watches exist, so a firing condition could be seen.
                for selector in re.findall(r"\b(?:wmdist_\w+|up\{[^}]*\})", expr):
                    assert query(prom, selector)["data"]["result"], (name, selector)
                if name in source.unhealthy_alerts:
                    assert res["data"]["result"], f"{name} should fire on this source: {expr}"
                else:
                    assert not res["data"]["result"], f"{name} fired on a healthy source: {res}"
