"""The live test's data source: a short real training run (the runtime with the fake
algorithm from tests/runtime) whose driver serves the wmdist exporter."""
from __future__ import annotations

import contextlib
import io
import threading
from pathlib import Path
from typing import Iterator

from tests.deploy.scripted_run import Source
from wmdist.config.loader import load_config
from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.roles.setup import build_algorithm
from wmdist.telemetry.publish import Telemetry
from wmdist.runtime.topology import build
from wmdist.runtime.train import env_spec_or_error

FAKE = str(Path(__file__).parents[1] / "runtime" / "fake.yaml")


@contextlib.contextmanager
def real_run(tmp_path: Path, minutes: float = 2.0) -> Iterator[Source]:
    """Train in a background thread until the block ends (or `minutes` pass)."""
    cfg = load_config(FAKE, [f"run.dir={tmp_path}", f"run.max_minutes={minutes}", "metrics.enabled=true",
                             "reanalyze.num=1", "eval.every_seconds=2", "run.log_every_seconds=0.5"])
    spec = env_spec_or_error(cfg)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    topo = build(cfg, spec, run_dir, build_algorithm(cfg, spec, 0).step_fields())
    tele = Telemetry(cfg, run_dir, io.StringIO())
    driver = Driver(topo, Counters(), on_tick=tele.update)
    thread = threading.Thread(target=driver.run, name="train", daemon=True)
    thread.start()
    try:
        yield Source(port=tele.hub.port, unhealthy_alerts=set())
    finally:
        driver.request_stop()
        thread.join(timeout=60)
        tele.close()
        topo.shutdown()
