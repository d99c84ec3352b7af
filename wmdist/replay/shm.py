"""ShmSegment: one shard's ring arrays, index and header in one POSIX shared-memory segment.

Layout (each array 64-byte aligned, all views of the one mapping):
  header   [32] int64    magic, layout hash, run token, count, clock, head, closed, stale reads,
                         the indexing in flight
  fheader  [4] float64   max_priority
  counters [32] int64    the shard's counters (`shard_shm.COUNTERS` order)
  meta     [C] per slot  stamp, version, episode, steps, born, gen, lease, commit,
                         c_version, c_episode, c_steps (int64), priority, lease_t (float64)
  mask     [C, T] bool
  f_<name> [C, T, ...]   one ring array per field

Names are `segment_prefix(run_name, run_dir) + "s<i>"`: the run name (for whoever lists
/dev/shm) and a hash of run dir and name, so two runs never share a name and nothing of the
machine's paths shows. A random token per replay service, kept in the header, tells a
restarted shard actor (same token: re-attach, data intact) from a stale segment of an
earlier service of that run (other token: unlinked and created afresh).

Lifetime: Python 3.11's resource tracker unlinks every segment a process created or
attached when that process dies; that would lose a SIGKILLed shard's data, so segments are
untracked in every process except one that asks to `keep_with_process` them (the driver:
its tracker unlinks them if the driver itself dies). A clean close unlinks them.
"""
from __future__ import annotations

import hashlib
import os
import re
import sys
from dataclasses import dataclass
from multiprocessing import resource_tracker
from multiprocessing.shared_memory import SharedMemory

import numpy as np

from wmdist.algos.base import FieldSpec

MAGIC = 0x776D64697374_3231  # "wmdist" + 21: a segment this module formatted
H_MAGIC, H_LAYOUT, H_TOKEN, H_COUNT, H_CLOCK, H_HEAD, H_CLOSED, H_STALE = range(8)
# an indexing in flight (see `ShmShard._index`): inserts counted before it, first write id of
# an actor-call insert (-1: a drain of client commits), and the flag (set last, cleared last)
H_IBASE, H_IFIRST, H_IFLIGHT = range(8, 11)
# index (written by the shard), then the commit record a client writes into a reserved slot
META_I64 = ("stamp", "version", "episode", "steps", "born", "gen", "lease", "commit", "c_version", "c_episode",
            "c_steps")
META_F64 = ("priority", "lease_t")
_ALIGN = 64
SHM_DIR = "/dev/shm"  # where Linux lists POSIX segments (sweeps and free-space checks only)

_KEPT: set[str] = set()  # names this process leaves to its resource tracker (see `keep_with_process`)


class ShmUnavailable(RuntimeError):
    """No shared memory here (no /dev/shm, too little room, or a segment of another layout)."""


@dataclass(frozen=True)
class Layout:
    """Byte offsets of every array of one shard's segment."""

    arrays: tuple[tuple[str, str, tuple[int, ...], int], ...]  # (name, dtype, shape, offset)
    size: int
    digest: int  # 62-bit hash of fields, capacity and T: attaching checks it

    @staticmethod
    def of(fields: dict[str, FieldSpec], capacity: int, seq_len: int) -> "Layout":
        C, T = capacity, seq_len
        parts: list[tuple[str, str, tuple[int, ...]]] = [
            ("header", "int64", (32,)), ("fheader", "float64", (4,)), ("counters", "int64", (32,))]
        parts += [(f"m_{k}", "int64", (C,)) for k in META_I64] + [(f"m_{k}", "float64", (C,)) for k in META_F64]
        parts += [("mask", "bool", (C, T))]
        parts += [(f"f_{k}", np.dtype(s.dtype).name, (C, T, *s.shape)) for k, s in sorted(fields.items())]
        out, off = [], 0
        for name, dt, shape in parts:
            out.append((name, dt, tuple(int(x) for x in shape), off))
            off += -(-int(np.prod(shape)) * np.dtype(dt).itemsize // _ALIGN) * _ALIGN
        key = repr([(n, d, s) for n, d, s, _ in out]).encode()
        return Layout(tuple(out), off, int.from_bytes(hashlib.sha1(key).digest()[:8], "little") >> 2)


def segment_prefix(run_name: str, run_dir: str) -> str:
    """Prefix of a run's segment names (no machine path: the run dir enters only hashed)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", run_name)[:24]
    h = hashlib.sha1(f"{os.path.abspath(run_dir)}\0{run_name}".encode()).hexdigest()[:8]
    return f"wmdist-{safe}-{h}-"


def _open(name: str, create: bool, size: int = 0) -> SharedMemory:
    """SharedMemory left out of this process's resource tracker (unless kept): a process
    that dies must not take the segment with it."""
    if sys.version_info >= (3, 13):
        return SharedMemory(name, create=create, size=size, track=name in _KEPT)
    shm = SharedMemory(name, create=create, size=size)
    if name not in _KEPT:
        resource_tracker.unregister(shm._name, "shared_memory")  # noqa: SLF001 - the name it registered
    return shm


def _unlink(name: str) -> bool:
    """Remove a segment's name (mappings stay valid until closed); False if it was gone."""
    try:
        shm = _open(name, create=False)
    except FileNotFoundError:
        return False
    if sys.version_info < (3, 13) and name not in _KEPT:
        resource_tracker.register(shm._name, "shared_memory")  # noqa: SLF001 - unlink() unregisters it
    try:
        shm.unlink()  # (and unregisters it: a kept name is no longer kept)
    except FileNotFoundError:
        pass
    _KEPT.discard(name)
    shm.close()
    return True


def keep_with_process(name: str) -> None:
    """This process's resource tracker unlinks `name` when this process dies (the driver
    does this for its shards' segments; `release` undoes it)."""
    if name not in _KEPT:
        _KEPT.add(name)
        resource_tracker.register("/" + name, "shared_memory")


def release(name: str) -> None:
    """Undo `keep_with_process` (the segment stays)."""
    if name in _KEPT:
        _KEPT.discard(name)
        resource_tracker.unregister("/" + name, "shared_memory")


def drop(name: str) -> None:
    """Unlink `name` if it is still there, and stop keeping it."""
    _unlink(name)
    release(name)


def sweep(prefix: str) -> list[str]:
    """Unlink every segment named `prefix*` (stale ones of an earlier start of the run)."""
    try:
        names = [n for n in os.listdir(SHM_DIR) if n.startswith(prefix)]
    except OSError:
        return []
    return [n for n in names if _unlink(n)]


def room(size: int) -> bool:
    """Whether /dev/shm can hold `size` more bytes (a full tmpfs turns a write into SIGBUS)."""
    try:
        st = os.statvfs(SHM_DIR)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize >= size + (64 << 20)


class ShmSegment:
    """Numpy views of one shard's segment: `header`, `fheader`, `counters`, `meta[k]` [C],
    `mask` [C, T] and `data[field]` [C, T, ...]."""

    def __init__(self, shm: SharedMemory, layout: Layout, fresh: bool) -> None:
        self.shm, self.layout, self.fresh = shm, layout, fresh
        self.name = shm.name.lstrip("/")
        v = {n: np.ndarray(shape, np.dtype(dt), buffer=shm.buf, offset=off) for n, dt, shape, off in layout.arrays}
        self.header, self.fheader, self.counters, self.mask = v["header"], v["fheader"], v["counters"], v["mask"]
        self.meta = {k[2:]: a for k, a in v.items() if k.startswith("m_")}
        self.data = {k[2:]: a for k, a in v.items() if k.startswith("f_")}

    @property
    def token(self) -> int:
        return int(self.header[H_TOKEN])

    @classmethod
    def attach(cls, name: str, fields: dict[str, FieldSpec], capacity: int, seq_len: int,
               token: int | None = None) -> "ShmSegment":
        """Map an existing segment (raises FileNotFoundError, or ShmUnavailable when its
        layout or token is not the expected one)."""
        layout = Layout.of(fields, capacity, seq_len)
        shm = _open(name, create=False)
        if shm.size < layout.size:
            shm.close()
            raise ShmUnavailable(f"shared-memory segment {name} is smaller than its layout")
        seg = cls(shm, layout, fresh=False)
        h = seg.header
        if h[H_MAGIC] != MAGIC or h[H_LAYOUT] != layout.digest or (token is not None and h[H_TOKEN] != token):
            seg.close()
            raise ShmUnavailable(f"shared-memory segment {name} belongs to another replay service")
        return seg

    @classmethod
    def open(cls, name: str, fields: dict[str, FieldSpec], capacity: int, seq_len: int, token: int) -> "ShmSegment":
        """The shard's segment: re-attached when it holds this service's data (`fresh` False:
        the shard actor was restarted), else created empty (`fresh` True)."""
        try:
            return cls.attach(name, fields, capacity, seq_len, token)
        except FileNotFoundError:
            pass
        except ShmUnavailable:
            _unlink(name)  # an earlier service's segment under this run's name: stale
        layout = Layout.of(fields, capacity, seq_len)
        if not room(layout.size):
            raise ShmUnavailable(f"{SHM_DIR} has no room for {layout.size} bytes")
        seg = cls(_open(name, create=True, size=layout.size), layout, fresh=True)  # zero-filled by the kernel
        seg.header[H_LAYOUT], seg.header[H_TOKEN] = layout.digest, token
        seg.header[H_MAGIC] = MAGIC  # last: a segment is attachable only once its header is complete
        return seg

    def close(self) -> None:
        """Drop this process's mapping (views of it must be gone; otherwise it stays mapped)."""
        self.header = self.fheader = self.counters = self.mask = None  # type: ignore[assignment]
        self.meta, self.data = {}, {}
        try:
            self.shm.close()
        except BufferError:  # a view is still referenced somewhere: the mapping goes with the process
            pass

    def unlink(self) -> None:
        self.header[H_CLOSED] = 1
        _unlink(self.name)
