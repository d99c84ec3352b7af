"""tune_malloc keeps a freed 24 MB block in the heap: glibc would otherwise mmap it afresh
(and fault its pages in again) on every learner update. Each case runs in a fresh process,
because glibc's own dynamic threshold would hide the difference after one free."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

PROBE = r"""
import ctypes, ctypes.util, json, sys
from wmdist.runtime.malloc import tune_malloc

class MallInfo2(ctypes.Structure):
    _fields_ = [(k, ctypes.c_size_t) for k in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.mallinfo2.restype = MallInfo2
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
tuned = tune_malloc() if sys.argv[1] == "tune" else False
before = libc.mallinfo2()
p = libc.malloc(24 << 20)
ctypes.memset(p, 1, 24 << 20)
during = libc.mallinfo2()
libc.free(p)
after = libc.mallinfo2()
print(json.dumps({"tuned": tuned, "mmapped": during.hblkhd - before.hblkhd, "kept_free": after.fordblks}))
"""


def _probe(mode: str) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")
def test_tuned_process_serves_large_blocks_from_the_heap_and_keeps_them():
    plain, tuned = _probe("plain"), _probe("tune")
    assert plain["mmapped"] >= 24 << 20  # glibc's default: a fresh mapping, unmapped on free
    assert tuned["tuned"] is True
    assert tuned["mmapped"] == 0
    assert tuned["kept_free"] >= 24 << 20  # freed, not trimmed: the next update reuses the pages
