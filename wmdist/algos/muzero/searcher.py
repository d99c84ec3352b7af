"""One batched MCTS over B roots with the MuZero network as the model (used by the policy,
the reanalyzer and the self-play bench)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from wmdist.algos.muzero.fast_conv import FastConvInference
from wmdist.algos.muzero.fast_mlp import FastMLPInference
from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.algos.muzero.rules_model import RulesModel
from wmdist.envs.boardgames.rules_batch import BatchRules
from wmdist.nets.support import support_to_scalar
from wmdist.search.api import SearchConfig, search


@dataclass
class SearchResult:
    visit_counts: np.ndarray  # [B, A]
    policy_target: np.ndarray  # [B, A] float32: visit distribution (Gumbel: the improved policy)
    root_value: np.ndarray  # [B] float32 search value of each root
    action: np.ndarray  # [B] the search's own choice (used with Gumbel)
    net_seconds: float  # time spent in network calls
    total_seconds: float  # time of the whole call


class Searcher:
    """Runs `wmdist.search.search` with `net` as the model; counts network time."""

    def __init__(self, net: MuZeroNet, cfg: SearchConfig, value_support: int, reward_support: int,
                 two_player: bool, device: torch.device, rules: BatchRules | None = None) -> None:
        self.net, self.cfg = net, cfg
        self.value_support, self.reward_support = value_support, reward_support
        self.two_player = two_player
        self.device = device
        self._net_seconds = 0.0
        # the tree keeps every node's latent in host memory (wmdist.search.latents): on an accelerator
        # each simulation moves the gathered [B, ...] latents in and the new ones back out
        self.on_host = torch.device(device).type == "cpu"
        # the MLP network's recurrent call as flat functional ops (bit-identical, ~2x cheaper on the CPU);
        # None: the module path
        self.fast = FastMLPInference.build(net, value_support, reward_support) if self.on_host else None
        # a conv network's BatchNorms folded into its convs (~1.2-1.4x cheaper on the CPU); for
        # EfficientZero the base network under its value-prefix and consistency heads. None: the module path
        self.conv = FastConvInference.build(getattr(net, "base", net)) if self.on_host else None
        # rules: the tree steps true positions and the network only evaluates them (algo.tree_model)
        self.rules_model = RulesModel(rules, self._evaluate) if rules is not None else None
        if cfg.value_prefix and not net.has_value_prefix:
            raise ValueError("algo.search.value_prefix needs a network with a value-prefix head (algo.name: efficientzero)")

    def _recurrent_prefix(self, latents: tuple, actions: np.ndarray, reset: np.ndarray):
        """Value-prefix mode: latents are (s [B, *latent], h [B, H], c [B, H]); the LSTM state
        starts from zeros where `reset` [B] (the parent's depth is a multiple of the horizon)."""
        t = time.perf_counter()
        with torch.no_grad():
            s, h, c = (self._in(x) for x in latents)
            keep = torch.as_tensor(~np.asarray(reset, bool), device=self.device)[:, None].to(h.dtype)  # [B, 1]
            a = torch.as_tensor(np.asarray(actions), dtype=torch.int64, device=self.device)
            over = {} if self.conv is None else {"base": self.conv}  # the folded conv base, else the network's own
            nxt, (h2, c2), prefix_logits, p_logits, v_logits = self.net.recurrent_inference_prefix(
                s, a, (h * keep, c * keep), **over)
            prefix = support_to_scalar(prefix_logits.float(), self.reward_support).cpu().numpy()
            value = support_to_scalar(v_logits.float(), self.value_support).cpu().numpy()
            logits = p_logits.float().cpu().numpy()
        self._net_seconds += time.perf_counter() - t
        return prefix, value, logits, (self._out(nxt), self._out(h2), self._out(c2))

    def _recurrent(self, latents: torch.Tensor, actions: np.ndarray):
        t = time.perf_counter()
        if self.fast is not None:
            out = self.fast.recurrent(latents, actions)
            self._net_seconds += time.perf_counter() - t
            return out
        with torch.no_grad():
            a = torch.as_tensor(np.asarray(actions), dtype=torch.int64, device=self.device)
            model = self.conv if self.conv is not None else self.net
            nxt, r_logits, p_logits, v_logits = model.recurrent_inference(self._in(latents), a)
            reward = support_to_scalar(r_logits.float(), self.reward_support).cpu().numpy()
            value = support_to_scalar(v_logits.float(), self.value_support).cpu().numpy()
            logits = p_logits.float().cpu().numpy()
        self._net_seconds += time.perf_counter() - t
        return reward, value, logits, self._out(nxt)

    def _evaluate(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rules mode: the network's value [B] and policy logits [B, A] of true positions."""
        t = time.perf_counter()
        with torch.no_grad():
            _, p_logits, v_logits = self.net.initial_inference(torch.as_tensor(obs, device=self.device))
            value = support_to_scalar(v_logits.float(), self.value_support).cpu().numpy()
            logits = p_logits.float().cpu().numpy()
        self._net_seconds += time.perf_counter() - t
        return value, logits

    def _in(self, x: torch.Tensor) -> torch.Tensor:
        """A gathered host latent onto the network's device (a no-op on the CPU)."""
        return x if self.on_host else x.to(self.device, non_blocking=True)

    def _out(self, x: torch.Tensor) -> torch.Tensor:
        """A new latent into host memory for the tree (a no-op on the CPU)."""
        return x if self.on_host else x.cpu()

    @torch.no_grad()
    def run(self, obs: np.ndarray, legal: np.ndarray, to_play: np.ndarray | None, rng: np.random.Generator,
            add_noise: bool, temperature: float = 1.0) -> SearchResult:
        start = time.perf_counter()
        self._net_seconds = 0.0
        obs_t = torch.as_tensor(np.ascontiguousarray(obs), device=self.device)
        latent, p_logits, v_logits = self.net.initial_inference(obs_t)
        root_value = support_to_scalar(v_logits.float(), self.value_support).cpu().numpy()
        root_logits = p_logits.float().cpu().numpy()
        self._net_seconds += time.perf_counter() - start
        fn = self._recurrent
        if self.cfg.value_prefix:  # the LSTM state lives with each node's latent in the tree
            latent, fn = (latent, *self.net.initial_state(len(obs_t), self.device)), self._recurrent_prefix
        latent = tuple(self._out(x) for x in latent) if isinstance(latent, tuple) else self._out(latent)
        if self.rules_model is not None:
            latent, fn = self.rules_model.root(obs), self.rules_model
        out = search(latent, root_logits, root_value, legal, to_play, fn, self.cfg, rng,
                     temperature=temperature, add_noise=add_noise, two_player=self.two_player)
        counts = np.asarray(out.visit_counts, dtype=np.float32)
        if self.cfg.gumbel:
            target = np.asarray(out.policy, dtype=np.float32)
        else:
            target = counts / np.maximum(counts.sum(-1, keepdims=True), 1.0)
        return SearchResult(counts, target, np.asarray(out.root_value, np.float32), np.asarray(out.action),
                            self._net_seconds, time.perf_counter() - start)
