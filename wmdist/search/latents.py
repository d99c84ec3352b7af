"""Latent store: every node's latent kept as raw bytes in the search buffer ([B, N, W] words).

Leaves (numpy arrays or CPU torch tensors, leading dim B) are packed side by side into a
row of W 8-byte words (each leaf's slot 8-byte aligned). The numba kernels copy rows in and
out by node index as words, so one simulation costs two row copies per batch row
whatever the dtype, and `recurrent_fn` receives numpy / torch views of the gathered rows
(torch via from_numpy, zero-copy) in the same nested tuple/list structure as the root
latents. A store is reused by later searches with the same latent signature."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmdist.search.layout import GATHERED, STAGED

try:  # torch is a project dependency, but search works on numpy alone
    import torch
except ImportError:  # pragma: no cover
    torch = None


def _is_tensor(x: Any) -> bool:
    return torch is not None and isinstance(x, torch.Tensor)


def _tensor_to_numpy(t: Any) -> np.ndarray:
    """Zero-copy numpy view of a CPU tensor (detached if it requires grad)."""
    try:
        return t.numpy()
    except RuntimeError:  # requires grad
        return t.detach().numpy()
    except TypeError as exc:  # not on the CPU
        raise ValueError(f"latent tensors must be on the CPU, got device {t.device}") from exc


def _flatten(tree: Any) -> tuple[list[Any], Any]:
    """Leaves in order and a structure spec: None for a leaf, else (type, [child specs])."""
    if isinstance(tree, (tuple, list)):
        leaves: list[Any] = []
        specs = []
        for item in tree:
            sub_leaves, sub_spec = _flatten(item)
            leaves.extend(sub_leaves)
            specs.append(sub_spec)
        return leaves, (type(tree), specs)
    if isinstance(tree, np.ndarray) or _is_tensor(tree):
        return [tree], None
    raise ValueError(f"latents must be numpy arrays, torch tensors or tuples/lists of them, got {type(tree).__name__}")


def _unflatten(spec: Any, leaves: list[Any], pos: int = 0) -> tuple[Any, int]:
    if spec is None:
        return leaves[pos], pos + 1
    kind, child_specs = spec
    items = []
    for child in child_specs:
        item, pos = _unflatten(child, leaves, pos)
        items.append(item)
    return kind(items), pos


@dataclass(frozen=True)
class _Slot:
    is_torch: bool
    dtype: np.dtype
    shape: tuple[int, ...]  # per-row shape (without B)
    offset: int  # byte offset in the row
    nbytes: int


def _numpy_dtype(leaf: Any) -> np.dtype:
    if not _is_tensor(leaf):
        return leaf.dtype
    if leaf.device.type != "cpu":
        raise ValueError(f"latent tensors must be on the CPU, got device {leaf.device}")
    try:
        return torch.empty(0, dtype=leaf.dtype).numpy().dtype
    except TypeError as exc:
        raise ValueError(f"latent tensor dtype {leaf.dtype} has no numpy equivalent") from exc


def signature(latents: Any) -> tuple:
    """Hashable description of a latent structure (kinds, dtypes, shapes): equal signatures
    can share one LatentStore."""
    if type(latents) is np.ndarray:  # the common case, without the general flattening
        return None, ((False, latents.dtype, latents.shape),)
    leaves, spec = _flatten(latents)
    return _frozen(spec), tuple((_is_tensor(x), x.dtype, tuple(x.shape)) for x in leaves)


def _frozen(spec: Any) -> Any:
    """The structure spec with its lists turned into tuples (hashable)."""
    if spec is None:
        return None
    kind, child_specs = spec
    return kind, tuple(_frozen(c) for c in child_specs)


class LatentStore:
    """Byte rows of the latents of B trees: the layout of one node's row (`words`), and
    the staging / gathered views of the io rows that `bind` attaches (the per-node rows
    live in the search buffer, touched only by the kernels)."""

    def __init__(self, root_latents: Any, batch: int) -> None:
        leaves, self._spec = _flatten(root_latents)
        slots = []
        offset = 0
        for leaf in leaves:
            if leaf.ndim < 1 or leaf.shape[0] != batch:
                raise ValueError(f"every latent leaf needs leading dim B={batch}, got shape {tuple(leaf.shape)}")
            dtype = np.dtype(_numpy_dtype(leaf))
            if dtype.hasobject:
                raise ValueError("latents with object dtype are not supported")
            shape = tuple(int(d) for d in leaf.shape[1:])
            nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
            slots.append(_Slot(_is_tensor(leaf), dtype, shape, offset, nbytes))
            offset += -(-nbytes // 8) * 8  # keep every slot 8-byte aligned
        self.words = max(offset, 8) // 8  # W
        self._slots = slots
        self._first = leaves[0]
        self._roots = leaves  # the root leaves, until bind() built the stagers

    def bind(self, io: np.ndarray) -> None:
        """Attach the io rows ([2, B, W] 8-byte words: staged, gathered) of a search buffer."""
        slots = self._slots
        self._staged_views = [self._typed_view(io[STAGED], s, as_torch=False) for s in slots]
        gathered_leaves = [self._typed_view(io[GATHERED], s) for s in slots]
        self.gathered_latents, _ = _unflatten(self._spec, gathered_leaves)
        # One leaf (the common case): stage() copies it without flattening, into a torch
        # view for torch leaves (Tensor.copy_ beats np.copyto(view, leaf.numpy()), whose
        # .numpy() alone costs microseconds) or a numpy view for numpy leaves.
        self.stage = self._stage_general
        if self._spec is None:
            self.stage = self._one_leaf_stager(self._typed_view(io[STAGED], slots[0]), self._first)
        elif self._spec[0] is tuple and all(c is None for c in self._spec[1]):
            # A flat tuple of leaves (EfficientZero's (latent, h, c)): one fast copy per leaf.
            stagers = [self._one_leaf_stager(self._typed_view(io[STAGED], slot), leaf, fallback=self._stage_general)
                       for slot, leaf in zip(slots, self._roots)]
            self.stage = self._tuple_stager(stagers)
        self._first = None
        self._roots = None

    def _tuple_stager(self, stagers: list) -> Callable[[Any], None]:
        """stage() for a flat tuple: each leaf through its own one-leaf stager (whose general
        path, for anything unlike the root's leaf, re-stages the whole tuple)."""
        general, n = self._stage_general, len(stagers)

        def stage_tuple(latents: Any) -> None:
            if type(latents) is not tuple or len(latents) != n:
                general(latents)
                return
            for stager, leaf in zip(stagers, latents):
                if stager(leaf, latents):
                    return  # the whole tuple went through the general path

        return stage_tuple

    def _one_leaf_stager(self, dst: Any, root: Any, fallback: Callable[[Any], None] | None = None) -> Callable:
        """stage() for a single leaf: the checks and the copy inline, the general path
        for anything that does not look like the root. As a leaf of a tuple (`fallback`
        given), it is called as (leaf, whole) and returns True when it staged `whole` by the
        general path instead."""
        general, dtype, shape = self._stage_general, root.dtype, tuple(root.shape)
        if fallback is not None:
            general = fallback
        if _is_tensor(root):
            tensor = torch.Tensor

            def stage_tensor(latents: Any, whole: Any = None) -> bool:
                # a grad-tracking copy_ would build a graph: the general path detaches
                if (isinstance(latents, tensor) and latents.dtype is dtype and latents.shape == shape
                        and not latents.requires_grad):
                    dst.copy_(latents)
                    return False
                general(latents if whole is None else whole)
                return True

            return stage_tensor
        ndarray = np.ndarray

        def stage_array(latents: Any, whole: Any = None) -> bool:
            if type(latents) is ndarray and latents.dtype is dtype and latents.shape == shape:
                dst[...] = latents
                return False
            general(latents if whole is None else whole)
            return True

        return stage_array

    @staticmethod
    def _typed_view(buf: np.ndarray, slot: _Slot, as_torch: bool = True) -> Any:
        """A [B, *shape] view of the slot's bytes (numpy, or torch sharing the memory)."""
        raw = buf.view(np.uint8)[:, slot.offset : slot.offset + slot.nbytes]
        view = raw.view(slot.dtype).reshape((buf.shape[0],) + slot.shape)
        assert np.shares_memory(view, buf)
        return torch.from_numpy(view) if (slot.is_torch and as_torch) else view

    def _stage_general(self, latents: Any) -> None:
        """Copy `latents` (same structure, shapes and kinds as the roots) into the staging
        row (`stage` is this, or a faster equivalent for a single leaf)."""
        leaves, _ = _flatten(latents)
        if len(leaves) != len(self._slots):
            raise ValueError(f"recurrent_fn returned {len(leaves)} latent leaves, expected {len(self._slots)}")
        for leaf, slot, view in zip(leaves, self._slots, self._staged_views):
            if tuple(leaf.shape[1:]) != slot.shape or leaf.shape[0] != view.shape[0]:
                raise ValueError(
                    f"latent leaf shape {tuple(leaf.shape)} differs from the root's {(view.shape[0],) + slot.shape}"
                )
            if slot.is_torch:
                if not _is_tensor(leaf):
                    raise ValueError("latent leaf changed from torch tensor to numpy array")
                np.copyto(view, _tensor_to_numpy(leaf), casting="same_kind")
            else:
                if _is_tensor(leaf):
                    raise ValueError("latent leaf changed from numpy array to torch tensor")
                np.copyto(view, leaf, casting="same_kind")
