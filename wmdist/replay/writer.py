"""SequenceWriter: cuts E parallel step streams into fixed-length windows (no Ray).

A collector calls `add(step, version)` once per vector-env step; each field is `[E, ...]`.
Each env fills a preallocated window `[T, ...]` per field. A window is complete when it
holds T steps (the next window of the same episode then starts with the last `overlap`
steps) or when the env's step has `last=True` (the window is zero-padded, `mask = 0`
after the end). Only complete windows are returned by `pop()`: a sequence becomes
visible to replay only when complete.

With `pack=True` an episode's end does not close its window: the next episode of that env
continues it (its first step has `first=True`), so every window holds T real steps. For
learners that reset their state at `first` inside a window (Dreamer): short episodes then
fill whole windows instead of padding, and the rate limiter's count of inserted sequences
stays a count of real steps.
"""
from __future__ import annotations

import numpy as np

from wmdist.algos.base import FieldSpec
from wmdist.replay.batch import SequenceBatch, check_field


class SequenceWriter:
    def __init__(self, fields: dict[str, FieldSpec], seq_len: int, overlap: int, num_envs: int,
                 pack: bool = False) -> None:
        if seq_len < 1:
            raise ValueError(f"seq_len must be >= 1, got {seq_len}")
        if not 0 <= overlap < seq_len:
            raise ValueError(f"overlap must be in [0, {seq_len - 1}], got {overlap}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if "last" in fields and fields["last"] != FieldSpec((), "bool"):
            raise ValueError("field 'last' must be declared as FieldSpec((), 'bool')")
        self.fields = dict(fields)
        self.T, self.overlap, self.E, self.pack = seq_len, overlap, num_envs, pack
        E, T = num_envs, seq_len
        self._buf = {k: np.zeros((E, T, *s.shape), dtype=s.dtype) for k, s in self.fields.items()}  # [E, T, ...]
        self._ver = np.zeros((E, T), dtype=np.int64)  # [E, T] policy version per step
        self._pos = np.zeros(E, dtype=np.int64)  # [E] next free step in each env's window
        self._episode = np.arange(E, dtype=np.int64)  # [E] current episode id per env
        self._window_episode = self._episode.copy()  # [E] episode id of each window's first step
        self._next_episode = E
        self._done: list[tuple[dict[str, np.ndarray], int, int, int]] = []  # (window, n_real, version, episode)

    def add(self, step: dict[str, np.ndarray], version: int = 0, env_ids: np.ndarray | None = None) -> None:
        """One step for all E envs (or only for `env_ids`, each field then `[len(env_ids), ...]`,
        e.g. the final observations of the envs whose episode just ended); closes the
        episodes whose `last` is True."""
        env = np.arange(self.E) if env_ids is None else np.asarray(env_ids, dtype=np.int64)
        if env.size and (env.min() < 0 or env.max() >= self.E or len(np.unique(env)) != env.size):
            raise ValueError(f"env_ids must be distinct ids in [0, {self.E}), got {env.tolist()}")
        E = int(env.size)
        for name, spec in self.fields.items():
            if name not in step:
                raise ValueError(f"field '{name}' is missing from the step")
            check_field(name, step[name], spec, (E,))
        if "last" not in self.fields:
            if "last" not in step:
                raise ValueError("field 'last' is missing from the step")
            check_field("last", step["last"], FieldSpec((), "bool"), (E,))
        pos = self._pos[env]
        for name, buf in self._buf.items():
            buf[env, pos] = step[name]
        self._ver[env, pos] = int(version)
        self._pos[env] += 1
        last = np.asarray(step["last"], bool)
        if self.pack:  # an ended episode is continued by the env's next one in the same window
            for j in np.flatnonzero(last):
                self._new_episode(int(env[j]))
            last = np.zeros_like(last)
        for j in np.flatnonzero(last | (self._pos[env] == self.T)):
            self._emit(int(env[j]), bool(last[j]))

    def _emit(self, i: int, last: bool) -> None:
        n = int(self._pos[i])
        window = {}
        for name, buf in self._buf.items():
            w = buf[i].copy()  # [T, ...]
            w[n:] = 0  # padding after the episode's end
            window[name] = w
        self._done.append((window, n, int(self._ver[i, :n].min()), int(self._window_episode[i])))
        if last:
            self._pos[i] = 0
            self._new_episode(i)
        else:  # the next window of this episode starts with the last `overlap` steps
            k = self.overlap
            for buf in self._buf.values():
                buf[i, :k] = buf[i, self.T - k:]
            self._ver[i, :k] = self._ver[i, self.T - k:]
            self._pos[i] = k
        self._window_episode[i] = self._episode[i]

    def discard(self, env_ids) -> None:
        """Drop the unfinished windows of these envs (their episode is abandoned)."""
        for i in np.atleast_1d(np.asarray(env_ids, dtype=np.int64)):
            if not 0 <= i < self.E:
                raise ValueError(f"env id {i} out of range [0, {self.E})")
            self._pos[i] = 0
            self._new_episode(i)
            self._window_episode[i] = self._episode[i]

    def _new_episode(self, i: int) -> None:
        self._episode[i] = self._next_episode
        self._next_episode += 1

    def pending(self) -> int:
        """Complete windows waiting for `pop()`."""
        return len(self._done)

    def pop(self) -> SequenceBatch:
        """The complete windows since the last pop, stacked `[N, T, ...]` (N may be 0)."""
        done, self._done = self._done, []
        T = self.T
        if not done:
            return SequenceBatch(
                {k: np.zeros((0, T, *s.shape), dtype=s.dtype) for k, s in self.fields.items()},
                np.zeros((0, T), dtype=bool), np.zeros(0, np.int64), np.zeros(0, np.int64))
        data = {k: np.stack([w[k] for w, _, _, _ in done]) for k in self.fields}
        n_real = np.array([n for _, n, _, _ in done])
        mask = np.arange(T)[None, :] < n_real[:, None]  # [N, T]
        version = np.array([v for _, _, v, _ in done], dtype=np.int64)
        episode = np.array([e for _, _, _, e in done], dtype=np.int64)
        return SequenceBatch(data, mask, version, episode)
