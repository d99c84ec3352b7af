"""Helpers for the deploy tests: the project's dashboards and rules, and a real Prometheus."""
from __future__ import annotations

import contextlib
import json
import shutil
import socket
import subprocess
import time
import urllib.parse
import urllib.request
from pathlib import Path
from typing import Iterator

import yaml

REPO = Path(__file__).resolve().parents[2]
DEPLOY = REPO / "deploy"


def dashboard_queries() -> list[tuple[str, str]]:
    """(panel title, PromQL) for every target of every panel of every dashboard."""
    out = []
    for path in sorted((DEPLOY / "grafana" / "dashboards").glob("*.json")):
        dash = json.loads(path.read_text())
        panels = list(dash["panels"])
        panels += [p for row in dash["panels"] for p in row.get("panels", [])]  # collapsed rows
        for p in panels:
            for t in p.get("targets", []):
                out.append((f"{path.stem}: {p['title']} [{t['refId']}]", t["expr"]))
    return out


def alert_rules() -> list[tuple[str, str]]:
    """(alert name, expression) of every alerting rule."""
    doc = yaml.safe_load((DEPLOY / "prometheus" / "alerts.yml").read_text())
    return [(r["alert"], r["expr"]) for g in doc["groups"] for r in g["rules"] if "alert" in r]


def promtool(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    exe = shutil.which("promtool")
    assert exe, "promtool not installed (make system-deps installs the prometheus package)"
    return subprocess.run([exe, *args], capture_output=True, text=True, cwd=cwd, timeout=60)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def running_prometheus(config: Path, storage: Path) -> Iterator[str]:
    """Debian's prometheus on a free loopback port; yields its base URL and stops it after."""
    exe = shutil.which("prometheus")
    assert exe, "prometheus not installed (make system-deps installs it)"
    port = free_port()
    log = open(storage.parent / "prometheus.log", "w")
    proc = subprocess.Popen(
        [exe, f"--config.file={config}", f"--storage.tsdb.path={storage}",
         f"--web.listen-address=127.0.0.1:{port}", "--log.level=warn"],
        stdout=log, stderr=subprocess.STDOUT,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 30
        while True:
            assert proc.poll() is None, (storage.parent / "prometheus.log").read_text()
            try:
                if urllib.request.urlopen(base + "/-/ready", timeout=2).status == 200:
                    break
            except OSError:
                pass
            assert time.monotonic() < deadline, "prometheus did not become ready in 30 s"
            time.sleep(0.2)
        yield base
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        log.close()


def query(base: str, expr: str) -> dict:
    """Instant query through the HTTP API; returns the decoded response (status, data or error)."""
    url = base + "/api/v1/query?" + urllib.parse.urlencode({"query": expr})
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return json.loads(r.read())
    except urllib.error.HTTPError as e:  # 400/422 carry the parse or execution error as JSON
        return json.loads(e.read())
