"""Session-wide fixtures: one real local Ray instance per test session."""
from __future__ import annotations

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# Ray workers inherit the driver's environment: let them import `tests.*` (fake algorithm, slow env).
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (_ROOT, os.environ.get("PYTHONPATH", "")) if p)


@pytest.fixture(scope="session")
def ray_session():
    """A real local Ray instance with 2 logical CPUs (started once; ~5 s)."""
    import ray

    if not ray.is_initialized():
        ray.init(
            address="local",  # always a fresh instance, never another process's cluster
            num_cpus=2,
            include_dashboard=False,
            log_to_driver=False,
            configure_logging=False,
            object_store_memory=256 * 1024**2,
        )
    yield ray
    ray.shutdown()


@pytest.fixture
def nothing_starts(monkeypatch):
    """`wmdist train` with its run replaced by a failure: a pre-start check must stop it first."""
    from wmdist.runtime import train as train_mod

    def started(*args, **kwargs):
        raise AssertionError("the run started: the check did not stop it first")

    monkeypatch.setattr(train_mod, "_run", started)
