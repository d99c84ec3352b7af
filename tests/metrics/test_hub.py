"""MetricsHub: every declared metric served with its type over HTTP on loopback; bad input refused."""
from __future__ import annotations

import math
import urllib.request

import pytest
from prometheus_client.parser import text_string_to_metric_families

from wmdist.telemetry.metrics import METRICS, MetricDef, MetricsHub, _check_table, snapshot_key

REQUIRED = {
    "wmdist_env_steps_total", "wmdist_env_steps_per_second", "wmdist_episodes_total",
    "wmdist_episode_return", "wmdist_episode_length", "wmdist_learner_updates_total",
    "wmdist_learner_updates_per_second", "wmdist_learner_loss", "wmdist_learner_nan_skips_total",
    "wmdist_replay_size_steps", "wmdist_replay_inserts_total", "wmdist_replay_samples_total",
    "wmdist_replay_drops_total", "wmdist_limiter_wait_seconds_total", "wmdist_weights_version",
    "wmdist_weights_version_gap", "wmdist_actor_restarts_total", "wmdist_busy_seconds_total",
    "wmdist_reanalyzed_sequences_total", "wmdist_policy_lag_drops_total",
}


def _labels_for(d: MetricDef) -> dict[str, str]:
    """One valid label set for a declared metric."""
    return {k: (d.allowed[k][0] if k in d.allowed else "x0") for k in d.labels}


def _scrape(url: str) -> dict[str, tuple[str, list]]:
    body = urllib.request.urlopen(url, timeout=10).read().decode()
    return {f.name: (f.type, f.samples) for f in text_string_to_metric_families(body)}


def test_the_table_declares_every_required_name_once_with_conventions():
    assert REQUIRED <= set(METRICS)
    for name, d in METRICS.items():
        assert (d.type == "counter") == name.endswith("_total"), name
        assert d.help.strip(), name


def test_hub_serves_every_declared_metric_with_its_type_on_loopback():
    with MetricsHub() as hub:
        assert hub.url.startswith("http://127.0.0.1:")
        assert hub._server.server_address[0] == "127.0.0.1"  # bound to loopback, not 0.0.0.0
        expected = {}
        for i, (name, d) in enumerate(METRICS.items()):
            labels = _labels_for(d)
            hub.set(name, float(i + 1), **labels)
            expected[name] = (d.type, labels, float(i + 1))
        families = _scrape(hub.url)
        for name, (typ, labels, value) in expected.items():
            fam = name[: -len("_total")] if typ == "counter" else name  # the parser strips _total
            assert fam in families, name
            got_type, samples = families[fam]
            assert got_type == typ, name
            match = [s for s in samples if s.name == name and s.labels == labels]
            assert len(match) == 1 and match[0].value == value, (name, samples)


def test_counters_are_set_to_running_totals_and_snapshot_is_flat():
    with MetricsHub() as hub:
        hub.set("wmdist_env_steps_total", 100)
        hub.set("wmdist_env_steps_total", 250)  # a total, not an increment
        hub.set("wmdist_learner_loss", 0.5, name="value")  # a label may be called `name`
        hub.set("wmdist_replay_drops_total", 3, shard="1", reason="stale_priority")
        snap = hub.snapshot()
        assert snap["wmdist_env_steps_total"] == 250.0
        assert snap["wmdist_learner_loss{name=value}"] == 0.5
        assert snap["wmdist_replay_drops_total{shard=1,reason=stale_priority}"] == 3.0
        assert snapshot_key("wmdist_replay_drops_total", reason="r", shard="2") == "wmdist_replay_drops_total{shard=2,reason=r}"
        samples = _scrape(hub.url)["wmdist_env_steps"][1]
        assert [s.value for s in samples if s.name == "wmdist_env_steps_total"] == [250.0]


@pytest.mark.parametrize(
    "name, value, labels, message",
    [
        ("wmdist_not_declared", 1.0, {}, "undeclared metric"),
        ("wmdist_episode_return", 1.0, {}, "takes labels"),
        ("wmdist_episode_return", 1.0, {"role": "train", "shard": "0"}, "takes labels"),
        ("wmdist_env_steps_total", 1.0, {"role": "train"}, "takes labels"),
        ("wmdist_episode_return", 1.0, {"role": "test"}, "not one of"),
        ("wmdist_limiter_wait_seconds_total", 1.0, {"side": "both"}, "not one of"),
        ("wmdist_env_steps_total", -1.0, {}, "finite total >= 0"),
        ("wmdist_env_steps_total", math.nan, {}, "finite total >= 0"),
        ("wmdist_weights_version", "7", {}, "must be a number"),
    ],
)
def test_bad_sets_are_refused_with_a_clear_error(name, value, labels, message):
    hub = MetricsHub()
    with pytest.raises(ValueError, match=message):
        hub.set(name, value, **labels)
    assert "wmdist_not_declared" not in hub.snapshot()


def test_two_hubs_in_one_process_do_not_share_state_and_close_frees_the_port():
    with MetricsHub() as a, MetricsHub() as b:
        a.set("wmdist_weights_version", 3)
        assert b.snapshot()["wmdist_weights_version"] == 0.0
        assert a.port != b.port
        url = a.url
    with pytest.raises(OSError):
        urllib.request.urlopen(url, timeout=2)


def test_table_conventions_are_enforced():
    with pytest.raises(ValueError, match="end in '_total'"):
        _check_table({"wmdist_steps": MetricDef("counter", "h")})
    with pytest.raises(ValueError, match="start with 'wmdist_'"):
        _check_table({"steps_total": MetricDef("counter", "h")})
    with pytest.raises(ValueError, match="port"):
        MetricsHub(port=70000)
