"""Search-time inference of `ConvNet` with each BatchNorm folded into its convolution.

In eval mode a BatchNorm is an affine map per channel, so conv -> BN is one conv with scaled
weights and a bias: w' = w * g / sqrt(var + eps), b' = beta - mean * g / sqrt(var + eps)
(Ioffe & Szegedy 2015, Alg. 2, at inference). The dynamics conv reads the latent concatenated
with one-hot action planes; its action half is the same map for every latent, so it is a
table [A, C, h, w] added after the latent half (the conv is linear in its input channels).
A simulation's recurrent call then runs 2 + 2 x blocks convolutions with their biases and
ReLUs, no BatchNorm and no concatenation. Measured with the MinAtar presets (AMD EPYC, AVX2,
one thread; BENCHMARKS.md, Self-play): self-play 1.13-1.15x more env steps per CPU second for
MuZero, 1.08-1.10x for EfficientZero (`wmdist bench selfplay`); the convolutions' own
arithmetic, which folding leaves as it is, is the rest. The arithmetic is the module's up to float rounding
(tests/algos/muzero/test_fast_conv.py checks it against `ConvNet` in eval mode).

Folded weights are rebuilt when any weight or BN statistic was written or moved since the last
fold (each tensor's in-place version counter and storage), so loading new weights in place
(`load_state_dict`, as `set_weights` does) needs no call here.
"""
from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from wmdist.algos.muzero.networks import scale_latent
from wmdist.algos.muzero.networks_conv import ConvNet, _Head
from wmdist.nets.resnet import ResidualBlock

Folded = tuple[torch.Tensor, torch.Tensor]  # conv weight [Cout, Cin, k, k], bias [Cout]


def fold(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> Folded:
    """conv -> BN (eval) as one conv's (weight, bias)."""
    scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)  # [Cout]
    w = conv.weight * scale[:, None, None, None]
    b = bn.bias - bn.running_mean * scale
    if conv.bias is not None:
        b = b + conv.bias * scale
    return w.contiguous(), b.contiguous()


def _tower(x: torch.Tensor, blocks: list[tuple[Folded, Folded]]) -> torch.Tensor:
    """`nets.resnet.ResidualBlock`s with folded convs; keeps [B, C, h, w]."""
    for (w1, b1), (w2, b2) in blocks:
        y = torch.relu(F.conv2d(x, w1, b1, padding=1))
        x = torch.relu(x + F.conv2d(y, w2, b2, padding=1))
    return x


class FastConvInference:
    """`transition`, `reward`, `predict` and `recurrent_inference` of a `ConvNet` in eval mode."""

    def __init__(self, net: ConvNet) -> None:
        self.net = net
        # every weight and BN statistic, listed once (walking the modules costs ~170 us a call);
        # loading weights writes these tensors in place (load_state_dict), which bumps their versions
        self._watch = [*net.parameters(), *net.buffers()]
        self._stamp: tuple = ()

    @staticmethod
    def build(net: nn.Module) -> "FastConvInference | None":
        """The fast path for exactly `ConvNet` (subclasses may change the arithmetic), else None."""
        return FastConvInference(net) if type(net) is ConvNet else None

    def _refresh(self) -> None:
        """Fold again if any weight or statistic was written since the last fold."""
        stamp = tuple((t.data_ptr(), t._version) for t in self._watch)  # new storage (`.to`) or writes
        if stamp == self._stamp:
            return
        n = self.net
        with torch.inference_mode():
            w, b = fold(n.dyn_conv, n.dyn_bn)
            c = n.dyn_conv.out_channels
            self.dyn = (w[:, :c].contiguous(), b)  # the latent's half
            self._action_w = w[:, c:].contiguous()  # [C, A, 3, 3]
            self._table: torch.Tensor | None = None  # built for the first latent's side (any h, w)
            self.dyn_tower = [self._block(blk) for blk in n.dyn_tower]
            self.pred_tower = [self._block(blk) for blk in n.pred_tower]
            self.heads = {name: fold(head.conv, head.bn) for name, head in
                          (("reward", n.reward_head), ("policy", n.policy_head), ("value", n.value_head))
                          if head is not None}  # EfficientZero's value prefix drops the reward head
        self._stamp = stamp  # folding reads the tensors only

    @staticmethod
    def _block(blk: ResidualBlock) -> tuple[Folded, Folded]:
        return fold(blk.conv1, blk.bn1), fold(blk.conv2, blk.bn2)

    def _actions(self, a: torch.Tensor, hh: int, ww: int) -> torch.Tensor:
        """[B] actions -> the action planes' share of the dynamics conv [B, C, h, w]."""
        if self._table is None or self._table.shape[-2:] != (hh, ww):
            planes = torch.eye(self.net.num_actions, dtype=self._action_w.dtype, device=self._action_w.device)
            planes = planes[:, :, None, None].expand(-1, -1, hh, ww).contiguous()  # [A, A, h, w]: plane a of action a
            self._table = F.conv2d(planes, self._action_w, None, padding=1)  # [A, C, h, w]
        return self._table[a]

    def _head(self, name: str, head: _Head, x: torch.Tensor) -> torch.Tensor:
        w, b = self.heads[name]
        return head.fc(torch.relu(F.conv2d(x, w, b)).flatten(1))

    def transition(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`ConvNet.transition`: (next latent [B, C, h, w] scaled, the tower's output the reward head reads)."""
        self._refresh()
        with torch.inference_mode():
            w, b = self.dyn
            x = torch.relu(F.conv2d(latent, w, b, padding=1) + self._actions(action, *latent.shape[-2:]))
            x = _tower(x, self.dyn_tower)
            return scale_latent(x), x

    def reward(self, features: torch.Tensor) -> torch.Tensor:
        """The reward head's logits [B, 2Sr+1]."""
        with torch.inference_mode():
            return self._head("reward", self.net.reward_head, features)

    def predict(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`ConvNet.predict`: (policy logits [B, A], value logits [B, 2Sv+1])."""
        self._refresh()
        with torch.inference_mode():
            x = _tower(latent, self.pred_tower)
            return self._head("policy", self.net.policy_head, x), self._head("value", self.net.value_head, x)

    def recurrent_inference(self, latent: torch.Tensor, action: torch.Tensor):
        """`MuZeroNet.recurrent_inference`: (next latent, reward logits, policy logits, value logits)."""
        nxt, features = self.transition(latent, action)
        logits, value = self.predict(nxt)
        return nxt, self.reward(features), logits, value
