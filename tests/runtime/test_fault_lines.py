"""The one line a failed role's error becomes (wmdist/runtime/faults.py)."""
from ray.exceptions import OutOfMemoryError

from wmdist.runtime.faults import one_line, out_of_memory, root_cause

# Ray 2.x's text for a worker its memory monitor killed (a paragraph; the driver used to cut it at 400 chars)
RAY_OOM = (
    "Task was killed due to the node running low on memory.\n"
    "Memory on the node (IP: 10.0.0.5, ID: 8d1f) where the lease (actor ID: 51c0, lease ID: 77aa, name=LearnerRole"
    ".__init__, pid=17117, memory used=0.71GB) was running was 22.39GB / 23.47GB (0.954), which exceeds the memory "
    "usage threshold of 0.95. Ray killed this worker (ID: 0fe2) because it was the most recently scheduled task; "
    "to see more information about memory usage on this node, use `ray logs raylet.out -ip 10.0.0.5`.\n"
    "Refer to the documentation on how to address the out of memory issue: https://docs.ray.io/en/latest/ray-"
    "observability/user-guides/debug-apps/debug-memory.html. Consider provisioning more memory on this node or "
    "reducing task parallelism by requesting more CPUs per task. Set max_restarts and max_task_retries to enable "
    "retry when the task crashes due to OOM. To adjust the kill threshold, set the environment variable "
    "`RAY_memory_usage_threshold` when starting Ray. To disable worker killing, set the environment variable "
    "`RAY_memory_monitor_refresh_ms` to zero.")


def test_a_memory_kill_reads_as_one_line_with_the_usage():
    err = OutOfMemoryError(RAY_OOM)
    for line in (one_line(err), root_cause(err)):
        assert "\n" not in line
        assert line.startswith("OutOfMemoryError: Ray's memory monitor killed it")
        assert "22.39GB / 23.47GB" in line and "learner.batch_size" in line
        assert "docs.ray.io" not in line


def test_a_memory_kill_wrapped_as_a_cause_is_found():
    outer = RuntimeError("the learner call failed")
    outer.__cause__ = OutOfMemoryError("no usage figures here")
    assert out_of_memory(outer) == ("OutOfMemoryError: Ray's memory monitor killed it: the machine's memory ran "
                                    "short; other jobs on the machine, or lower learner.batch_size / "
                                    "replay.capacity_steps")


def test_other_errors_keep_their_last_line():
    assert out_of_memory(ValueError("x")) is None
    assert one_line(ValueError("first\nlast words")) == "ValueError: last words"
    assert root_cause(RuntimeError("Traceback ...\n  File x\nKeyError: 'obs'")) == "KeyError: 'obs'"
