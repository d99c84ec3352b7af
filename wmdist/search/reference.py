"""Slow reference search: one root, dict-based nodes, recursion. Used only by tests.

It implements the conventions documented in `api.py` as directly as possible, with the
floating-point operations in the same order as `kernels.py` so results compare with ==.
`step(latent, action) -> (reward, value, logits [A], next_latent)` is the model for one root.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

from wmdist.search.api import SearchConfig
from wmdist.search.noise import considered_visit_sequence

RESCALE_EPS = 1e-8


def softmax(logits: list[float], mask: list[bool] | None = None) -> list[float]:
    keep = [True] * len(logits) if mask is None else mask
    mx = max(x for x, k in zip(logits, keep) if k)
    exps = [math.exp(x - mx) if k else 0.0 for x, k in zip(logits, keep)]
    total = 0.0
    for e, k in zip(exps, keep):
        if k:
            total += e
    return [e / total for e in exps]


@dataclass
class Node:
    latent: Any
    logits: list[float]
    prior: list[float]
    raw_value: float
    reward: float = 0.0  # edge reward into this node
    prefix: float = 0.0  # value prefix (EfficientZero)
    depth: int = 0
    visits: int = 0
    value_sum: float = 0.0
    children: dict[int, "Node"] = field(default_factory=dict)

    def mean(self) -> float:
        return self.value_sum / self.visits


@dataclass
class ReferenceResult:
    visit_counts: list[int]
    root_value: float
    q_values: list[float]  # completed Q (illegal 0)
    improved_policy: list[float] | None  # Gumbel only
    gumbel_action: int | None  # Gumbel only


class ReferenceSearch:
    def __init__(self, step: Callable, config: SearchConfig, legal: list[bool], gumbel: list[float],
                 two_player: bool) -> None:
        self.step = step
        self.cfg = config
        self.legal = legal
        self.gumbel = gumbel
        self.gamma_sign = config.discount * (-1.0 if two_player else 1.0)
        self.lo = math.inf
        self.hi = -math.inf
        self.num_actions = len(legal)

    # --- values -------------------------------------------------------------------
    def q(self, child: Node) -> float:
        return child.reward + self.gamma_sign * child.mean()

    def normalize(self, q: float) -> float:
        """(q - min) / (max - min) clipped to [0, 1]; 0 while the tree has no Q range."""
        if not self.hi > self.lo:
            return 0.0
        return min(max((q - self.lo) * (1.0 / (self.hi - self.lo)), 0.0), 1.0)

    def completed(self, node: Node, is_root: bool) -> tuple[list[float], list[float]]:
        """(completed Q, sigma) per action; Gumbel MuZero eq. 33 and eq. 8."""
        mask = self.legal if is_root else [True] * self.num_actions
        probs = softmax(node.logits, mask)
        visited = [a for a in range(self.num_actions) if a in node.children]
        sum_n = sum_p = sum_pq = 0.0
        max_n = 0.0
        for a in visited:
            child = node.children[a]
            sum_n += child.visits
            sum_p += probs[a]
            sum_pq += probs[a] * self.q(child)
            max_n = max(max_n, float(child.visits))
        v_mix = (node.raw_value + sum_n / sum_p * sum_pq) / (1.0 + sum_n) if sum_n > 0 else node.raw_value
        raw = [0.0] * self.num_actions
        for a in range(self.num_actions):
            if mask[a]:
                raw[a] = self.q(node.children[a]) if a in node.children else v_mix
        lo = min(raw[a] for a in range(self.num_actions) if mask[a])
        hi = max(raw[a] for a in range(self.num_actions) if mask[a])
        scale = (self.cfg.gumbel_c_visit + max_n) * self.cfg.gumbel_c_scale
        span = max(hi - lo, RESCALE_EPS)
        sigma = [scale * ((raw[a] - lo) / span) if mask[a] else 0.0 for a in range(self.num_actions)]
        return raw, sigma

    # --- selection ----------------------------------------------------------------
    def visits_of(self, node: Node, a: int) -> int:
        return node.children[a].visits if a in node.children else 0

    def select_puct(self, node: Node, is_root: bool) -> int:
        cfg = self.cfg
        n = float(node.visits)
        pb_c = (cfg.c1 + math.log((n + cfg.c2 + 1.0) / cfg.c2)) * math.sqrt(n)
        unvisited = self.normalize(node.value_sum / n) if cfg.unvisited_value == "parent" else 0.0
        scores = {}
        for a in range(self.num_actions):
            if is_root and not self.legal[a]:
                continue
            value_score = self.normalize(self.q(node.children[a])) if a in node.children else unvisited
            scores[a] = value_score + node.prior[a] * pb_c / (1.0 + self.visits_of(node, a))
        return max(scores, key=lambda a: (scores[a], -a))  # lowest index on ties

    def select_gumbel_root(self, node: Node) -> int:
        _, sigma = self.completed(node, True)
        m = min(self.cfg.gumbel_max_considered, sum(self.legal))
        target = considered_visit_sequence(m, self.cfg.num_simulations)[node.visits - 1]
        scores = {a: self.gumbel[a] + node.logits[a] + sigma[a]
                  for a in range(self.num_actions) if self.legal[a] and self.visits_of(node, a) == target}
        return max(scores, key=lambda a: (scores[a], -a))

    def select_gumbel_interior(self, node: Node) -> int:
        _, sigma = self.completed(node, False)
        improved = softmax([node.logits[a] + sigma[a] for a in range(self.num_actions)])
        total = float(sum(self.visits_of(node, a) for a in range(self.num_actions)))
        scores = {a: improved[a] - self.visits_of(node, a) / (1.0 + total) for a in range(self.num_actions)}
        return max(scores, key=lambda a: (scores[a], -a))

    def select(self, node: Node, is_root: bool) -> int:
        if not self.cfg.gumbel:
            return self.select_puct(node, is_root)
        return self.select_gumbel_root(node) if is_root else self.select_gumbel_interior(node)

    # --- one simulation -------------------------------------------------------------
    def expand(self, parent: Node, action: int) -> Node:
        reset = parent.depth % self.cfg.lstm_horizon == 0
        if self.cfg.value_prefix:
            r, v, logits, latent = self.step(parent.latent, action, reset)
        else:
            r, v, logits, latent = self.step(parent.latent, action)
        logits = [float(x) for x in logits]
        child = Node(latent=latent, logits=logits, prior=softmax(logits), raw_value=float(v),
                     depth=parent.depth + 1)
        if self.cfg.value_prefix:
            child.prefix = float(r)
            child.reward = float(r) if reset else float(r) - parent.prefix
        else:
            child.reward = float(r)
        parent.children[action] = child
        return child

    def simulate(self, node: Node, is_root: bool) -> float:
        """Descend, expand one leaf, and return G from `node`'s view while backing up."""
        a = self.select(node, is_root)
        if a in node.children:
            child = node.children[a]
            g_child = self.simulate(child, False)
        else:
            child = self.expand(node, a)
            g_child = child.raw_value
            child.value_sum += g_child
            child.visits += 1
        q = self.q(child)
        self.lo, self.hi = min(self.lo, q), max(self.hi, q)
        g = child.reward + self.gamma_sign * g_child
        node.value_sum += g
        node.visits += 1
        return g


def reference_search(root_latent: Any, root_logits: list[float], root_value: float, legal: list[bool],
                     step: Callable, config: SearchConfig, dirichlet: list[float], gumbel: list[float],
                     add_noise: bool, two_player: bool = False) -> ReferenceResult:
    """Search one root; `dirichlet` / `gumbel` are that root's noise rows (see noise.py)."""
    search = ReferenceSearch(step, config, list(legal), [float(g) for g in gumbel], two_player)
    logits = [float(x) for x in root_logits]
    prior = softmax(logits, search.legal)
    frac = config.dirichlet_fraction if (add_noise and not config.gumbel) else 0.0
    if frac > 0:
        prior = [(1.0 - frac) * p + frac * float(d) if ok else p for p, d, ok in zip(prior, dirichlet, legal)]
    root = Node(latent=root_latent, logits=logits, prior=prior, raw_value=float(root_value),
                visits=1, value_sum=float(root_value))
    for _ in range(config.num_simulations):
        search.simulate(root, True)
    visits = [search.visits_of(root, a) for a in range(search.num_actions)]
    raw_q, sigma = search.completed(root, True)
    improved = action = None
    if config.gumbel:
        improved = softmax([root.logits[a] + sigma[a] for a in range(search.num_actions)], search.legal)
        top = max(visits[a] for a in range(search.num_actions) if legal[a])
        scores = {a: search.gumbel[a] + root.logits[a] + sigma[a]
                  for a in range(search.num_actions) if legal[a] and visits[a] == top}
        action = max(scores, key=lambda a: (scores[a], -a))
    return ReferenceResult(visits, root.mean(), raw_q, improved, action)
