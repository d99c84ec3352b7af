"""Actor handles handed to restartable actors travel by name (`wmdist/runtime/named.py`).

Ray prints an error line at start-up for every restartable actor whose constructor
arguments hold an actor handle (ray-project/ray#53727); the collectors, reanalyzers and the
evaluator get the replay client and the weight broker that way. With names, the line is
gone and a restarted actor still reaches the named one.
"""
from __future__ import annotations

import pickle
import subprocess
import sys
import textwrap

from wmdist.runtime.named import NamedHandle, actor_name, unwrap

RAY_LINE = "constructor arguments in the object store"


def test_a_named_handle_pickles_to_its_name_only():
    h = NamedHandle("wmdist-x-0-abc", handle=object())
    back = pickle.loads(pickle.dumps(h))
    assert back.name == "wmdist-x-0-abc" and back._handle is None
    raw = object()
    assert unwrap(NamedHandle("n", raw)) is raw and unwrap(raw) is raw
    assert actor_name("replay", 1) != actor_name("replay", 1)  # two runs in one namespace never clash


SCRIPT = textwrap.dedent("""
    import os, sys, time
    import ray
    from wmdist.runtime.named import NamedHandle
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)

    @ray.remote(num_cpus=0, max_restarts=-1)
    class Service:
        def ping(self):
            return "pong"

    @ray.remote(num_cpus=0, max_restarts=1, max_task_retries=0)
    class User:
        def __init__(self, service):
            self.service = service
        def call(self):
            return ray.get(self.service.ping.remote()), os.getpid()
        def die(self):
            os._exit(1)

    svc = NamedHandle("svc-test", Service.options(name="svc-test").remote())
    user = User.remote(svc)
    got, pid = ray.get(user.call.remote())
    try:
        ray.get(user.die.remote())
    except ray.exceptions.RayActorError:
        pass
    deadline = time.monotonic() + 60
    while True:  # Ray restarts it; the new process looks the service up by name
        try:
            again, pid2 = ray.get(user.call.remote(), timeout=10)
            break
        except (ray.exceptions.RayActorError, ray.exceptions.GetTimeoutError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)
    print("RESULT", got, again, pid != pid2, flush=True)
    sys.stderr.flush()
    print("CONTROL", file=sys.stderr, flush=True)
    ray.get(User.remote(svc.handle).call.remote())  # a raw handle: Ray's line (the check can fail)
    time.sleep(0.5)
""")


def test_a_restartable_actor_given_a_named_handle_gets_no_ray_error_and_survives_a_restart():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "RESULT pong pong True" in out.stdout, out.stdout + out.stderr[-3000:]
    before, _, after = out.stderr.partition("CONTROL")
    assert RAY_LINE not in before, before[-3000:]
    assert RAY_LINE in after, after[-3000:]  # the same Ray prints it for a raw handle
