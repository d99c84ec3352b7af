"""Waypoints toward a far goal from a graph over replay's embeddings (Search on the Replay Buffer,
Eysenbach et al. 2019, docs/reference.md).

The predictor is sure of a few steps, not of a route through a door: on nav:tworooms most failed
episodes are goals in the other room, where CEM's rollouts cross walls that the agent cannot
(BENCHMARKS.md, JEPA). The learner publishes the embeddings of P transitions it trained on
(`TransitionGraph`'s nodes 2i -> 2i+1 are one real step, z_t -> z_{t+1}); the graph joins them by
those steps (length 1) and by each node's k nearest neighbours in embedding space (length: their
distance over the median step's, so one step's worth of distance counts as one step). Neighbour
links longer than `link_max` median steps are dropped. (An embedding can fold the state space so
that frames on either side of a wall lie closer than one step, a shortcut through the wall; on
nav:tworooms a cut-off tight enough to drop those split the graph and planned worse: BENCHMARKS.md.)
At each decision the planner aims at the node `steps` along the shortest path from
the current embedding's nearest node to the goal's; within `steps` of the goal, at the goal itself.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra


class TransitionGraph:
    """Shortest paths over published transitions; `waypoints` maps goals to the embedding to plan toward."""

    def __init__(self, nodes: np.ndarray,  # [2P, D] z_t, z_{t+1} of each transition, interleaved
                 knn: int,  # neighbour links per node
                 link_max: float,  # the longest neighbour link, in median steps
                 ) -> None:
        if nodes.ndim != 2 or nodes.shape[0] < 2 or nodes.shape[0] % 2:  # (the nodes: [N <= 2P, D] distinct)
            raise ValueError(f"a transition graph needs [2P, D] embeddings, got {list(nodes.shape)}")
        # one node per distinct embedding: replay holds the same frame many times (a window sampled
        # again, an agent pressed against a wall), and copies would fill each other's k nearest
        uniq, inv = np.unique(np.asarray(nodes, np.float32), axis=0, return_inverse=True)
        self.nodes = torch.as_tensor(uniq)  # [N, D]
        n = self.nodes.shape[0]
        src, dst = inv.reshape(-1)[0::2], inv.reshape(-1)[1::2]  # [P] each: z_t -> z_{t+1}
        moved = src != dst  # a blocked step (no change) links nothing
        src, dst = src[moved], dst[moved]
        step = (self.nodes[src] - self.nodes[dst]).norm(dim=-1).numpy()  # [P']
        unit = max(float(np.median(step)), 1e-6) if len(step) else 1.0
        rows, cols, lens = [src], [dst], [np.ones(len(src))]
        k = min(knn, n - 1)
        if k > 0:
            d = torch.cdist(self.nodes, self.nodes)  # [N, N]
            d.fill_diagonal_(float("inf"))
            near_d, near_i = (t.numpy() for t in d.topk(k, largest=False))  # [N, k]
            keep = near_d <= link_max * unit
            a, b = np.repeat(np.arange(n), k)[keep.ravel()], near_i.ravel()[keep.ravel()]
            w = np.maximum(near_d.ravel()[keep.ravel()] / unit, 1e-6)  # a zero would read as no link
            rows += [a, b]  # neighbours link both ways
            cols += [b, a]
            lens += [w, w]
        # to the goal: shortest paths on the reversed graph from the goal (csr sums duplicates: keep
        # the shortest of parallel links by building from unique pairs)
        r, c, ln = np.concatenate(rows), np.concatenate(cols), np.concatenate(lens)
        order = np.lexsort((ln, c, r))
        r, c, ln = r[order], c[order], ln[order]
        first = np.ones(len(r), bool)
        first[1:] = (r[1:] != r[:-1]) | (c[1:] != c[:-1])
        self.reverse = csr_matrix((ln[first], (c[first], r[first])), shape=(n, n))  # [N, N] edge v -> u as u <- v
        self._paths: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def nearest(self, z: torch.Tensor) -> np.ndarray:
        """[E, D] -> the nearest node of each [E]."""
        return torch.cdist(z.float().cpu(), self.nodes).argmin(1).numpy()

    def to_goal(self, goal: int) -> tuple[np.ndarray, np.ndarray]:
        """(steps from every node to `goal` [N] (inf: no path), next node on that path [N] (-9999: none))."""
        if goal not in self._paths:
            dist, pred = dijkstra(self.reverse, directed=True, indices=goal, return_predecessors=True)
            self._paths[goal] = (dist, pred)  # pred on the reversed graph = the next node toward the goal
        return self._paths[goal]

    def waypoints(self, z: torch.Tensor,  # [E, D] the current embeddings
                  z_goal: torch.Tensor,  # [E, D] the goal images' embeddings
                  steps: float,  # how far along the path to aim, in steps
                  ) -> torch.Tensor:
        """[E, D]: per env the node `steps` along the shortest path to the goal's nearest node, or
        z_goal itself when the goal is that close or the graph has no path."""
        out = z_goal.clone()
        here, goal = self.nearest(z), self.nearest(z_goal)
        for e in range(z.shape[0]):
            dist, nxt = self.to_goal(int(goal[e]))
            node = int(here[e])
            if not np.isfinite(dist[node]) or dist[node] <= steps:
                continue
            target = dist[node] - steps  # walk toward the goal until `steps` of path are behind
            while nxt[node] >= 0 and dist[node] > target:
                node = int(nxt[node])
            out[e] = self.nodes[node].to(out)
        return out
