"""lower_priority: every thread of the process, those that exist and those started after, runs
at the new nice level, and calling it again does not lower it twice. Run in a child process
so the test runner itself keeps its priority."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

CHILD = textwrap.dedent("""
    import json, os, threading
    from wmdist.runtime.priority import lower_priority, niceness

    def level(tid):  # None for a thread that exited while we looked (a joined one lingers briefly)
        try:
            stat = open(f"/proc/self/task/{tid}/stat").read()
        except FileNotFoundError:
            return None
        return int(stat.rsplit(")", 1)[1].split()[16])

    stop = threading.Event()
    before = threading.Thread(target=stop.wait, daemon=True)  # a thread that exists before the call
    before.start()
    base = niceness()
    target = lower_priority(3)
    again = lower_priority(3, base=base)  # a second call from the role's call thread
    seen = {}
    after = threading.Thread(target=lambda: seen.setdefault("nice", niceness()))
    after.start(); after.join()
    levels = {level(t) for t in os.listdir("/proc/self/task")} - {None}
    stop.set(); before.join()
    print(json.dumps({"base": base, "target": target, "again": again, "levels": sorted(levels),
                      "inherited": seen["nice"], "unchanged": lower_priority(0)}))
""")


def test_every_thread_is_lowered_once_and_new_threads_inherit_it():
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    want = min(19, r["base"] + 3)
    assert r["target"] == want and r["again"] == want
    assert r["levels"] == [want]  # every thread, the one started before the call too
    assert r["inherited"] == want  # a thread started after
    assert r["unchanged"] == want  # by=0 leaves the level as it is
