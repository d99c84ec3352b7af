"""JEPA's waypoints on a graph of published transitions (`wmdist/algos/jepa/waypoints.py`): the
shortest paths against a plain Bellman-Ford loop, a route around a wall that a straight line would
cut, and the learner -> weights -> policy path."""
from __future__ import annotations

import numpy as np
import torch

from tests.algos.jepa.test_jepa_batchnorm import _batch
from tests.algos.jepa.test_jepa_learning import small_config
from wmdist.algos.jepa import Jepa
from wmdist.algos.jepa.model import GRAPH_KEY, JepaModel, load_model
from wmdist.algos.jepa.waypoints import TransitionGraph
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec


def _u_walk() -> np.ndarray:
    """Transitions along a U in the plane, 0.1 apart: up x = 0 from y = 0 to 1, across y = 1 to x = 0.6,
    down x = 0.6 to y = 0. The two legs are 0.6 apart (a wall between them), the ends ~6 steps apart
    as the crow flies and 26 steps along the U. Returned as [2P, 2] interleaved (z_t, z_{t+1})."""
    up = [(0.0, y / 10) for y in range(11)]
    across = [(x / 10, 1.0) for x in range(1, 7)]
    down = [(0.6, y / 10) for y in range(9, -1, -1)]
    path = np.array(up + across + down, np.float32)  # [27, 2]
    return np.stack([path[:-1], path[1:]], 1).reshape(-1, 2)  # [52, 2]


def _bellman_ford(graph: TransitionGraph, goal: int) -> np.ndarray:
    """Steps from every node to `goal` by relaxing every link N times: the obvious, slow reference."""
    fwd = graph.reverse.T.tocoo()  # [N, N] the original links u -> v
    dist = np.full(graph.nodes.shape[0], np.inf)
    dist[goal] = 0.0
    for _ in range(graph.nodes.shape[0]):
        for u, v, w in zip(fwd.row, fwd.col, fwd.data):
            dist[u] = min(dist[u], w + dist[v])
    return dist


def test_copies_of_a_frame_are_one_node_and_a_blocked_step_links_nothing():
    a, b, c = [0.0, 0.0], [0.1, 0.0], [0.2, 0.0]
    nodes = np.array([a, b, a, b, b, b, b, c], np.float32)  # a->b twice, b->b (blocked), b->c
    graph = TransitionGraph(nodes, knn=1, link_max=1.0)
    assert graph.nodes.shape[0] == 3
    dist, _ = graph.to_goal(2)  # the node of c (distinct points sort as a, b, c)
    np.testing.assert_allclose(dist, [2.0, 1.0, 0.0])


def test_shortest_paths_equal_a_plain_relaxation_loop():
    rng = np.random.default_rng(0)
    walk = np.cumsum(rng.normal(0, 0.1, (61, 3)), 0).astype(np.float32)  # a random walk in 3-d
    nodes = np.stack([walk[:-1], walk[1:]], 1).reshape(-1, 3)  # [120, 3]
    graph = TransitionGraph(nodes, knn=3, link_max=1.0)
    n = graph.nodes.shape[0]
    assert n == 61  # every frame but the walk's ends is in two transitions: one node each
    for goal in (0, n // 2, n - 1):
        dist, nxt = graph.to_goal(goal)
        np.testing.assert_allclose(dist, _bellman_ford(graph, goal), rtol=1e-9)
        # following `nxt` from any reachable node arrives, and its links add up to the distance
        for start in np.flatnonzero(np.isfinite(dist))[::7]:
            node, total = int(start), 0.0
            while node != goal:
                total += graph.reverse[int(nxt[node]), node]  # the link node -> next, stored reversed
                node = int(nxt[node])
            assert np.isclose(total, dist[start])


def test_links_join_steps_and_near_nodes_only():
    nodes = _u_walk()  # steps of 0.1; the legs 0.6 apart
    for link_max in (1.0, 6.5):
        graph = TransitionGraph(nodes, knn=len(nodes) - 1, link_max=link_max)  # every pair a candidate
        g = graph.nodes.numpy()  # [27, 2]: the U's distinct points
        assert len(g) == 27
        fwd = graph.reverse.T.tocoo()
        lengths = {}
        for u, v, w in zip(fwd.row, fwd.col, fwd.data):
            d = np.linalg.norm(g[u] - g[v])
            assert d <= 0.1 * link_max + 1e-6
            assert np.isclose(w, 1.0) or np.isclose(w, d / 0.1, atol=1e-5)
            lengths[u, v] = w
        # every transition is a link u -> v of length 1
        index = {tuple(p): i for i, p in enumerate(g)}
        for i in range(0, len(nodes), 2):
            assert np.isclose(lengths[index[tuple(nodes[i])], index[tuple(nodes[i + 1])]], 1.0)
        # across the gap (bottom of the left leg to the bottom of the right, 0.6 apart): only with a long link
        across = any(abs(g[u, 0] - g[v, 0]) > 0.5 for u, v in lengths)
        assert across == (link_max > 6)


def test_a_waypoint_follows_the_route_around_the_wall_not_the_straight_line():
    nodes = _u_walk()
    graph = TransitionGraph(nodes, knn=4, link_max=1.5)
    z = torch.tensor([[0.0, 0.05]])  # near the start of the left leg
    goal = torch.tensor([[0.6, 0.0]])  # the end of the right leg: 0.6 away straight across
    way = graph.waypoints(z, goal, steps=4.0)
    assert way[0, 1] > 0.2 and abs(float(way[0, 0])) < 1e-6  # up the left leg, away from the goal
    # the path from there: 26 steps; 4 along it is (0, 0.4)
    torch.testing.assert_close(way, torch.tensor([[0.0, 0.4]]))
    # a link across the gap (as a fold near a wall makes) is a shortcut: the waypoint heads across
    short = TransitionGraph(nodes, knn=len(nodes) - 1, link_max=6.5).waypoints(z, goal, steps=4.0)
    assert float(short[0, 0]) > 0.5
    # once within `steps` of the goal the goal itself is the target
    near = torch.tensor([[0.6, 0.2]])
    torch.testing.assert_close(graph.waypoints(near, goal, steps=4.0), goal)
    # no path (a goal node with no link in): the goal itself
    lone = np.concatenate([nodes, np.array([[5.0, 5.0], [5.1, 5.0]], np.float32)])
    torch.testing.assert_close(TransitionGraph(lone, knn=0, link_max=1.5).waypoints(z, torch.tensor([[5.1, 5.0]]), 4.0),
                               torch.tensor([[5.1, 5.0]]))


def test_the_learner_publishes_its_transitions_embeddings_and_the_policy_plans_toward_a_waypoint():
    spec = env_spec(EnvConfig(id="nav:tworooms"))
    cfg = small_config(graph_pairs=20)
    algo = Jepa(spec, cfg, seed=0)
    learner = algo.make_learner()
    batches = [_batch(s, b=4, t=4) for s in range(3)]
    batches[-1]["mask"][:, 2:] = 0  # the last batch's windows end after 2 real steps: 1 transition each
    for b in batches:
        learner.update(b)
    weights = learner.get_weights()
    nodes = weights[GRAPH_KEY]
    assert nodes.shape == (40, cfg.embed_dim)  # the latest 20 transitions: 4 of the last batch, 12, then 4 of the first
    # rows 2i, 2i+1 are the frames of one real step, embedded as the policy embeds (eval mode, these weights)
    model = JepaModel(cfg, spec.action_dim).eval()
    load_model(model, weights)  # the graph entry is not a parameter
    pairs = [np.stack([x["obs"][b, t, ..., :3], x["obs"][b, t + 1, ..., :3]])  # in batch order, row by row
             for x in batches for b in range(4) for t in range(3) if x["mask"][b, t + 1]]
    frames = np.concatenate(pairs[-20:])  # [40, 64, 64, 3]
    with torch.no_grad():
        want = model.encode(torch.as_tensor(frames)).numpy()
    np.testing.assert_allclose(nodes, want, rtol=1e-4, atol=1e-4)

    policy = algo.make_policy("cpu")
    policy.set_weights(weights, 1)
    obs = batches[0]["obs"][:, 0]  # [4, 64, 64, 6]
    action, _ = policy.act(obs, np.ones(4, bool), None, None, False)
    assert policy.graph is not None and np.asarray(action).shape == (4, 2)
    off = small_config()  # graph_pairs 0: nothing published, nothing built
    plain = Jepa(spec, off, seed=0).make_learner()
    plain.update(batches[0])
    assert GRAPH_KEY not in plain.get_weights()
