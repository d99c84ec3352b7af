"""Building blocks of the Dreamer networks that avoid work the naive way does.

A categorical latent z is 32 one-hots of 32 classes, so `z @ W` is the sum of 32 selected
rows of W (an embedding bag): 32*D adds instead of 1024*D multiply-adds. The straight-
through gradient still reaches the class probabilities through a zero-valued term whose
backward is the dense `grad @ W^T`. Layers that read several inputs ([h, z], [z, a], [h, e])
keep one weight block per input (`SplitLinear`) so nothing is concatenated, parts can be
precomputed for a whole sequence, and heads that read the same features share one matmul.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from wmdist.nets.mlp import ACTIVATIONS


@dataclass
class Latent:
    """A batch of stochastic states [N, ...].

    Categorical: `index` [N, S] sampled classes and, where gradients must flow, `probs`
    [N, S, C] (straight-through). Gaussian: `sample` [N, Z].
    """

    index: torch.Tensor | None = None
    probs: torch.Tensor | None = None
    sample: torch.Tensor | None = None
    classes: int = 0

    def dense(self) -> torch.Tensor:
        """[N, Z] features (straight-through one-hots for categoricals)."""
        if self.index is None:
            assert self.sample is not None
            return self.sample
        onehot = F.one_hot(self.index, self.classes).float()
        if self.probs is not None:
            onehot = onehot + self.probs - self.probs.detach()
        return onehot.flatten(-2)

    def detach(self) -> "Latent":
        return Latent(self.index, None, None if self.sample is None else self.sample.detach(), self.classes)

    def reshape(self, *lead: int) -> "Latent":
        def r(x: torch.Tensor | None, tail: int) -> torch.Tensor | None:
            return None if x is None else x.reshape(*lead, *x.shape[x.dim() - tail:])
        return Latent(r(self.index, 1), r(self.probs, 2), r(self.sample, 1), self.classes)


def compute_dtype(x: torch.Tensor) -> torch.dtype:
    """The dtype a matmul on `x`'s device produces here: autocast's if it is on, else x's."""
    if torch.is_autocast_enabled(x.device.type):
        return torch.get_autocast_dtype(x.device.type)
    return x.dtype


class _StraightThroughRows(torch.autograd.Function):
    """Value 0; gradient w.r.t. probs [N, Z] is grad_out @ W^T (the straight-through path).

    The backward matmul runs in `dtype`, the forward's compute dtype, as autocast runs a dense
    `onehot @ W`'s backward: bf16 under bf16 autocast. In fp32 it was the largest matmul of a
    continuous update ([H*N, U] x [U, 1024] for the heads, one per imagined step for the dynamics).
    """

    @staticmethod
    def forward(ctx, probs: torch.Tensor, weight: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(weight.to(dtype))  # no copy when dtype is already the weight's
        ctx.probs_dtype = probs.dtype
        return probs.new_zeros(probs.shape[0], weight.shape[1], dtype=dtype)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (weight,) = ctx.saved_tensors  # [Z, D] in the compute dtype
        return (grad.to(weight.dtype) @ weight.t()).to(ctx.probs_dtype), None, None


class _OneHotMatmul(torch.autograd.Function):
    """sum_s W[s * C + index[n, s]] for every row n: [N, S] indices, W [S*C, D] -> [N, D].

    Forward is an embedding bag, summed in `dtype` (bf16 under autocast, like a matmul
    there). The weight gradient scatters grad rows into the selected rows in the weight's
    own dtype, one index_add per latent variable (N*D adds each), avoiding the sort that
    embedding_bag's backward does.
    """

    @staticmethod
    def forward(ctx, index: torch.Tensor, weight: torch.Tensor, classes: int, dtype: torch.dtype) -> torch.Tensor:  # type: ignore[override]
        flat = index + torch.arange(index.shape[1], device=index.device) * classes  # [N, S]
        ctx.save_for_backward(flat)
        ctx.weight_shape, ctx.weight_dtype = weight.shape, weight.dtype
        return F.embedding_bag(flat, weight.to(dtype), mode="sum")

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (flat,) = ctx.saved_tensors
        grad = grad.to(ctx.weight_dtype)  # accumulate in fp32: a row can collect thousands of terms
        return None, onehot_weight_grad(flat, grad, ctx.weight_shape[0]), None, None


@torch.library.custom_op("wmdist::onehot_weight_grad", mutates_args=())
def onehot_weight_grad(flat: torch.Tensor, grad: torch.Tensor, rows: int) -> torch.Tensor:
    """[rows, D] weight gradient of `_OneHotMatmul`: grad [N, D] added into the rows flat [N, S] picked.

    An opaque op, so that torch.compile calls ATen's index_add here: inductor's own lowering of
    it is a scalar scatter loop, 2x slower than the whole eager update on the small V3 model.
    """
    grad_w = grad.new_zeros(rows, grad.shape[1])
    for s in range(flat.shape[1]):
        grad_w.index_add_(0, flat[:, s], grad)
    return grad_w


@onehot_weight_grad.register_fake
def _(flat: torch.Tensor, grad: torch.Tensor, rows: int) -> torch.Tensor:
    return grad.new_empty(rows, grad.shape[1])


_DENSE_ROWS = 64  # measured crossover: dense wins at 16 rows, the index_add path at 1024


def onehot_matmul(lat: Latent, weight: torch.Tensor, cols: int | None = None) -> torch.Tensor:
    """`lat.dense() @ weight[:, :cols]` computed as an embedding bag for categoricals -> [N, cols]."""
    w = weight if cols is None else weight[:, :cols]
    if lat.index is None:
        assert lat.sample is not None
        return lat.sample @ w
    if cols is not None:
        w = w.contiguous()
    if lat.index.shape[0] <= _DENSE_ROWS:  # a few rows (the observe loop): a dense matmul has less overhead
        return lat.dense() @ w
    dtype = compute_dtype(w)  # the embedding bag is not autocast: match the matmuls' dtype by hand
    if w.requires_grad and torch.is_grad_enabled():
        out = _OneHotMatmul.apply(lat.index, w, lat.classes, dtype)
    else:
        offsets = torch.arange(lat.index.shape[1], device=lat.index.device) * lat.classes
        out = F.embedding_bag(lat.index + offsets, w.to(dtype), mode="sum")
    if lat.probs is not None and lat.probs.requires_grad:
        out = out + _StraightThroughRows.apply(lat.probs.reshape(lat.index.shape[0], -1), w, dtype)
    return out


class SplitLinear(nn.Module):
    """y = sum_k x_k @ W_k + b over named inputs; a `Latent` input uses `onehot_matmul`.

    `cols` computes only the first `cols` outputs (a prefix of fused heads);
    `pre` adds a precomputed part (e.g. the embedding's share for a whole sequence).
    """

    def __init__(self, dims: dict[str, int], out: int, bias: bool = True) -> None:
        super().__init__()
        total = sum(dims.values())
        bound = 1.0 / math.sqrt(total)
        self.dims = dict(dims)
        self.weights = nn.ParameterDict(
            {k: nn.Parameter(torch.empty(d, out).uniform_(-bound, bound)) for k, d in dims.items()}
        )
        self.bias = nn.Parameter(torch.empty(out).uniform_(-bound, bound)) if bias else None
        self.out = out

    def part(self, name: str, x: torch.Tensor | Latent, cols: int | None = None) -> torch.Tensor:
        w = self.weights[name]
        if isinstance(x, Latent):
            return onehot_matmul(x, w, cols)
        return x @ (w if cols is None else w[:, :cols])

    def forward(
        self,
        parts: dict[str, torch.Tensor | Latent],
        pre: torch.Tensor | None = None,
        cols: int | None = None,
        scale: dict[str, torch.Tensor] | None = None,
    ) -> torch.Tensor:
        y = pre
        for name, x in parts.items():
            p = self.part(name, x, cols)
            if scale is not None and name in scale:
                p = p * scale[name].to(p.dtype)  # e.g. zero the previous latent where an episode starts
            # one dtype throughout: a mixed bf16 + fp32 add takes a slow path and makes fp32
            y = p if y is None else y + p.to(y.dtype)
        if self.bias is not None:
            b = self.bias if cols is None else self.bias[:cols]
            y = y + b.to(y.dtype)
        assert y is not None
        return y


def norm_act(width: int, act: str, norm: bool) -> nn.Sequential:
    return nn.Sequential(nn.LayerNorm(width, eps=1e-3) if norm else nn.Identity(), ACTIVATIONS[act]())


class GRUCell(nn.Module):
    """GRU with one fused gate matmul and optional LayerNorm (DreamerV2/V3 formulation).

    r, c, u = split(LN(W [x, h])); c = tanh(sigmoid(r) * c); u = sigmoid(u - 1);
    h' = u * c + (1 - u) * h. The -1 bias makes the cell keep its state early in training.
    """

    def __init__(self, in_dim: int, deter: int, norm: bool) -> None:
        super().__init__()
        self.lin = SplitLinear({"x": in_dim, "h": deter}, 3 * deter, bias=not norm)
        self.norm = nn.LayerNorm(3 * deter, eps=1e-3) if norm else nn.Identity()

    def forward(self, x: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        gates = self.norm(self.lin({"x": x, "h": h}))
        reset, cand, update = gates.chunk(3, -1)
        cand = torch.tanh(torch.sigmoid(reset) * cand)
        update = torch.sigmoid(update - 1)
        return torch.lerp(h.to(cand.dtype), cand, update)  # u * c + (1 - u) * h in one op


class Heads(nn.Module):
    """Several MLP heads over the same inputs sharing one first-layer matmul.

    heads: name -> output width; each head is `layers` hidden layers of `units` then a
    linear output. `forward(parts, upto=name)` evaluates the heads in declaration order up
    to and including `upto` only (the shared matmul is cut to that prefix).
    """

    def __init__(
        self, dims: dict[str, int], heads: dict[str, int], units: int, layers: int, act: str, norm: bool,
        zero_init: tuple[str, ...] = (),
    ) -> None:
        super().__init__()
        self.names = list(heads)
        self.units = units
        self.first = SplitLinear(dims, units * len(heads), bias=not norm)
        self.tails = nn.ModuleDict()
        for name, out in heads.items():
            mods: list[nn.Module] = [norm_act(units, act, norm)]
            for _ in range(layers - 1):
                mods += [nn.Linear(units, units, bias=not norm), norm_act(units, act, norm)]
            last = nn.Linear(units, out)
            if name in zero_init:  # V3: reward and critic start by predicting 0
                nn.init.zeros_(last.weight)
                nn.init.zeros_(last.bias)
            mods.append(last)
            self.tails[name] = nn.Sequential(*mods)

    def forward(self, parts: dict[str, torch.Tensor | Latent], upto: str | None = None) -> dict[str, torch.Tensor]:
        k = len(self.names) if upto is None else self.names.index(upto) + 1
        hidden = self.first(parts, cols=None if k == len(self.names) else k * self.units)
        chunks = hidden.split(self.units, -1)
        return {name: self.tails[name](chunks[i]) for i, name in enumerate(self.names[:k])}
