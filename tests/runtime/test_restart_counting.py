"""The driver's restart accounting, isolated from Ray: answers are fed in by hand."""
from __future__ import annotations

from types import SimpleNamespace

from wmdist.runtime.driver import Counters, Driver
from wmdist.runtime.roles.setup import process_tag
from wmdist.runtime.table import BUILTIN


def _driver(max_restarts: int = -1) -> Driver:
    cfg = SimpleNamespace(actors=SimpleNamespace(max_restarts=max_restarts))
    # only cfg and the table of roles are read outside run()
    return Driver(SimpleNamespace(cfg=cfg, roles=BUILTIN, local=False), Counters())


def test_new_process_counts_one_restart_and_same_process_none():
    d = _driver()
    for pid in (10, 10, 10):
        d._note_process("collector", 0, {"pid": pid, "restarted": False})
    assert d.c.restarts["collector"] == 0
    d._note_process("collector", 0, {"pid": 11, "restarted": True})
    d._note_process("collector", 0, {"pid": 11, "restarted": True})
    assert d.c.restarts["collector"] == 1
    d._note_process("collector", 1, {"pid": 12, "restarted": False})  # another actor's first answer
    assert d.c.restarts["collector"] == 1


def test_replacement_heard_first_is_a_restart():
    """Killed during start-up: no call failed and no earlier pid is known; the process says it
    is a replacement."""
    d = _driver()
    d._note_process("collector", 0, {"pid": 20, "restarted": True})
    assert d.c.restarts["collector"] == 1 and d.deaths[("collector", 0)] == 1


def test_failed_call_then_new_process_is_one_death():
    d = _driver(max_restarts=1)
    d._note_process("collector", 0, {"pid": 30, "restarted": False})
    assert not d._restarts_used_up("collector", 0)  # the in-flight call died
    assert not d._restarts_used_up("collector", 0)  # a retry failed while it restarts: same death
    d._note_process("collector", 0, {"pid": 31, "restarted": True})
    assert d.c.restarts["collector"] == 1 and d.deaths[("collector", 0)] == 1
    assert d._restarts_used_up("collector", 0)  # a second death is over the limit of 1


def test_same_process_after_a_failed_call_is_no_restart():
    """A call lost to a transient error (the actor stayed up) is not a restart."""
    d = _driver()
    d._note_process("evaluator", 0, {"pid": 40, "restarted": False})
    d._restarts_used_up("evaluator", 0)
    d._note_process("evaluator", 0, {"pid": 40, "restarted": False})
    assert d.c.restarts["evaluator"] == 0


def test_process_tag_outside_ray_is_an_original():
    tag = process_tag()
    assert tag["restarted"] is False and isinstance(tag["pid"], int)
