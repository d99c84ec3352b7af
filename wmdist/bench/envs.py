"""`wmdist bench envs`: env throughput against the raw simulators (see wmdist/envs/throughput.py)."""
from wmdist.envs.throughput import run  # noqa: F401
