"""Edge costs (eq. 11), EMA (eq. 13), Dijkstra vs. networkx, and the detour around a busy corridor."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest

from dynactivegs.errors import ConfigError
from dynactivegs.planning import stage as planning
from dynactivegs.planning._reference import edge_mean_along_reference, shortest_path_reference
from dynactivegs.planning.paths import (
    PLANNER_VARIANTS, PathConfig, dijkstra, edge_cost, edge_mean_along, ema_update, graph_arrays, path_polyline,
    shortest_path, thin_polyline, transfer_edge_values, variant_edge_cost,
)
from dynactivegs.rng import derive_rng
from dynactivegs.selection.voronoi import GraphArrays, VoronoiConfig, build_voronoi_graph, nearest_node

CELL = 0.05


def _random_graph(rng: np.random.Generator, n: int) -> tuple[nx.Graph, np.ndarray]:
    pts = rng.uniform(0, 10, size=(n, 2))
    G = nx.Graph()
    G.add_nodes_from(range(n))
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    for a in range(n):
        for b in np.argsort(d[a])[1:1 + int(rng.integers(1, 4))]:
            G.add_edge(a, int(b), length_m=float(d[a, b]))
    return G, pts


def test_dijkstra_costs_equal_networkx_on_seeded_random_graphs():
    # Costs must agree to float round-off (sums of the same edge costs in possibly different
    # order): rtol 1e-12. Paths may differ where two paths tie, so only costs are compared,
    # plus the returned path's own cost.
    rng = derive_rng(0, "test-dijkstra-twin")
    n_unreachable = 0
    for trial in range(25):
        n = int(rng.integers(2, 60))
        G, _ = _random_graph(rng, n)
        arrays = graph_arrays(G)
        cost = edge_cost(arrays.length_m, rng.uniform(0, 2, arrays.n_edges), float(rng.uniform(0, 5)))
        if trial % 5 == 0:
            cost = np.ones_like(cost)                 # many ties
        for _ in range(5):
            s, t = (int(x) for x in rng.integers(0, n, 2))
            path, c = shortest_path(arrays, cost, s, t)
            ref_path, ref_c = shortest_path_reference(arrays, cost, s, t)
            if not ref_path:
                n_unreachable += 1
                assert path == [] and c == float("inf")
                continue
            assert c == pytest.approx(ref_c, rel=1e-12, abs=0)
            assert path[0] == s and path[-1] == t
            lookup = {(a, b): k for k, (a, b) in enumerate(zip(arrays.u.tolist(), arrays.v.tolist()))}
            own = sum(cost[lookup[(min(a, b), max(a, b))]] for a, b in zip(path[:-1], path[1:]))
            assert own == pytest.approx(c, rel=1e-12)
    assert n_unreachable > 0                          # the disconnected case was exercised
    G, _ = _random_graph(rng, 5)
    arrays = graph_arrays(G)
    assert shortest_path(arrays, np.ones(arrays.n_edges), 3, 3) == ([3], 0.0)


def box(free: np.ndarray, x0: float, y0: float, x1: float, y1: float, value=True) -> None:
    h, w = free.shape
    xs = (np.arange(w) + 0.5) * CELL
    ys = (np.arange(h) + 0.5) * CELL
    free[np.ix_((ys >= y0) & (ys <= y1), (xs >= x0) & (xs <= x1))] = value


def two_rooms_with_a_direct_corridor_and_a_detour():
    free = np.zeros((120, 190), bool)
    box(free, 0.5, 0.5, 2.5, 2.5)                     # room A
    box(free, 6.5, 0.5, 8.5, 2.5)                     # room B
    box(free, 2.5, 1.2, 6.5, 1.8)                     # direct corridor, 4 m
    box(free, 1.0, 2.5, 2.0, 5.0)                     # detour: up from A,
    box(free, 1.0, 4.0, 8.0, 5.0)                     # across,
    box(free, 7.0, 2.5, 8.0, 5.0)                     # down into B
    busy = np.zeros(free.shape, np.float64)
    box(busy, 2.8, 1.0, 6.2, 2.0, 1.0)                # people keep walking in the direct corridor
    G = build_voronoi_graph(free, np.zeros_like(free), CELL, np.zeros(2), VoronoiConfig())
    return G, busy


def _through_corridor(xy: np.ndarray) -> bool:
    return bool(((xy[:, 0] > 3.0) & (xy[:, 0] < 6.0) & (xy[:, 1] < 2.0)).any())


def test_dyn_edge_detours_around_a_busy_corridor_that_shortest_goes_through():
    G, busy = two_rooms_with_a_direct_corridor_and_a_detour()
    arrays = graph_arrays(G)
    s, t = nearest_node(G, np.array([1.5, 1.5])), nearest_node(G, np.array([7.5, 1.5]))
    um = edge_mean_along(arrays, busy)
    routes = {}
    for variant in PLANNER_VARIANTS:
        cfg = PathConfig(variant=variant, motion_weight=4.0)
        path, _ = shortest_path(arrays, variant_edge_cost(cfg, arrays.length_m, um, um), s, t)
        xy = path_polyline(G, path)
        routes[variant] = (xy, float(np.hypot(*np.diff(xy, axis=0).T).sum()))
    assert _through_corridor(routes["shortest"][0])
    assert not _through_corridor(routes["dyn_edge"][0])
    assert routes["dyn_edge"][1] > routes["shortest"][1] + 4.0       # a real detour (about 6 m longer)
    assert (routes["dyn_edge"][0][:, 1] > 4.0).any()
    # with l_m = 0 the motion-aware planner is the shortest one
    path0, _ = shortest_path(arrays, variant_edge_cost(PathConfig("dyn_edge", 0.0), arrays.length_m, um, um), s, t)
    assert _through_corridor(path_polyline(G, path0))


def test_temporal_variant_remembers_a_busy_corridor_for_a_while():
    G, busy = two_rooms_with_a_direct_corridor_and_a_detour()
    arrays = graph_arrays(G)
    s, t = nearest_node(G, np.array([1.5, 1.5])), nearest_node(G, np.array([7.5, 1.5]))
    cfg_t = PathConfig("dyn_edge_temporal", motion_weight=4.0, ema_gamma=0.2)
    cfg_d = PathConfig("dyn_edge", motion_weight=4.0)
    ema = np.zeros(arrays.n_edges)
    for _ in range(10):                               # people walk there for 10 steps ...
        ema = ema_update(ema, edge_mean_along(arrays, busy), cfg_t.ema_gamma)
    now = edge_mean_along(arrays, np.zeros_like(busy))  # ... then the corridor is empty in this frame
    via = lambda cfg: _through_corridor(path_polyline(G, shortest_path(arrays, variant_edge_cost(cfg, arrays.length_m, now, ema), s, t)[0]))
    assert via(cfg_d)                                 # no memory: back through the corridor at once
    assert not via(cfg_t)                             # EMA: still avoids it
    for _ in range(30):
        ema = ema_update(ema, now, cfg_t.ema_gamma)
    assert via(cfg_t)                                 # after a long calm spell it is used again


def test_ema_is_eq_13():
    a = np.array([0.0, 1.0, 2.0])
    b = np.array([1.0, 1.0, 0.0])
    np.testing.assert_allclose(ema_update(a, b, 0.25), 0.75 * a + 0.25 * b)
    np.testing.assert_array_equal(ema_update(a, b, 1.0), b)
    x = np.zeros(3)
    for _ in range(200):
        x = ema_update(x, b, 0.1)
    np.testing.assert_allclose(x, b, atol=1e-8)
    np.testing.assert_array_equal(a, [0.0, 1.0, 2.0])  # inputs untouched


def test_edge_mean_along_equals_reference_and_transfer_keeps_values():
    G, _ = two_rooms_with_a_direct_corridor_and_a_detour()
    arrays = graph_arrays(G)
    rng = derive_rng(1, "test-edge-mean")
    vm = rng.uniform(0, 3, size=G.graph["shape"])
    fast = edge_mean_along(arrays, vm)
    ref = edge_mean_along_reference(G, vm)
    for k, (a, b) in enumerate(zip(arrays.u.tolist(), arrays.v.tolist())):
        assert fast[k] == pytest.approx(ref[(a, b)], rel=1e-12)
    # a uniform per-edge value survives a transfer onto the same graph; a fresh region gets the default
    vals = np.full(arrays.n_edges, 0.7)
    np.testing.assert_allclose(transfer_edge_values(arrays, vals, arrays, G.graph["shape"]), 0.7)
    left = np.array([G.nodes[a]["xy"][0] < 4.5 and G.nodes[b]["xy"][0] < 4.5 for a, b in zip(arrays.u, arrays.v)])
    # transfer from a graph of the left half only onto the full graph
    sub = G.edge_subgraph([(a, b) for (a, b), k in zip(zip(arrays.u.tolist(), arrays.v.tolist()), left) if k])
    mapping = {n: i for i, n in enumerate(sorted(sub.nodes))}
    half = graph_arrays(nx.relabel_nodes(sub, mapping))
    out = transfer_edge_values(half, np.full(half.n_edges, 2.0), arrays, G.graph["shape"], default=-1.0)
    right = np.array([G.nodes[a]["xy"][0] > 5.5 and G.nodes[b]["xy"][0] > 5.5 for a, b in zip(arrays.u, arrays.v)])
    assert np.all(out[left] == 2.0) and np.all(out[right] == -1.0)


def test_polyline_helpers():
    G, _ = two_rooms_with_a_direct_corridor_and_a_detour()
    path = list(nx.shortest_path(G, 0, G.number_of_nodes() - 1))
    xy = path_polyline(G, path)
    assert np.allclose(xy[0], G.nodes[path[0]]["xy"]) and np.allclose(xy[-1], G.nodes[path[-1]]["xy"])
    assert np.hypot(*np.diff(xy, axis=0).T).max() <= 2 * np.sqrt(2) * CELL + 1e-9
    thin = thin_polyline(xy, 0.5)
    assert np.allclose(thin[-1], xy[-1]) and len(thin) < len(xy) / 5


def test_config_validation():
    with pytest.raises(ConfigError):
        PathConfig(variant="teleport")  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        PathConfig(ema_gamma=0.0)
    with pytest.raises(ConfigError):
        PathConfig(motion_weight=-1.0)


def chain_graph(with_pair: bool) -> tuple[np.ndarray, GraphArrays]:
    """(node xy, arrays): 7 nodes 0.5 m apart along +x, and with ``with_pair`` a cut-off pair of nodes 7, 8 at
    (1.0, 0.6), (1.5, 0.6), joined to each other only."""
    xy = [[0.5 * i, 0.0] for i in range(7)] + ([[1.0, 0.6], [1.5, 0.6]] if with_pair else [])
    u, v = list(range(6)) + ([7] if with_pair else []), list(range(1, 7)) + ([8] if with_pair else [])
    return np.array(xy), GraphArrays(len(xy), np.array(u), np.array(v), np.full(len(u), 0.5),
                                     np.zeros(len(u) + 1, np.int64), np.zeros((0, 2), np.int64))


def test_the_path_starts_at_the_node_ahead_not_at_the_nearest_one_behind():
    xy, arrays = chain_graph(with_pair=False)                    # the target is the chain's last node
    to_target, pred = dijkstra(arrays, arrays.length_m, 6)

    class Sel:
        node_xy_m = xy
        node_leg_clear = np.ones(len(xy), bool)
    robot = np.array([0.35, 0.15])                                # nearest is node 1 (0.21 m), behind and to the right
    cfg = planning.PlanningConfig()
    assert planning._source(cfg, Sel, arrays, to_target, pred, robot, 0.0) == 2                 # facing +x: ahead
    assert planning._source(planning.PlanningConfig(source_radius_m=0.0), Sel, arrays, to_target, pred, robot, 0.0) == 1
    to_start, pred0 = dijkstra(arrays, arrays.length_m, 0)        # the target at the other end, behind the robot
    assert planning._source(cfg, Sel, arrays, to_start, pred0, robot, math.pi) == 0


def test_the_path_never_starts_at_a_node_the_robot_cannot_drive_to_straight():
    xy, arrays = chain_graph(with_pair=False)
    to_target, pred = dijkstra(arrays, arrays.length_m, 6)
    clear = np.ones(len(xy), bool)
    clear[2] = False                                              # say a low box stands between the robot and node 2

    class Sel:
        node_xy_m = xy
        node_leg_clear = clear
    robot = np.array([0.35, 0.15])
    cfg = planning.PlanningConfig()
    assert planning._source(cfg, Sel, arrays, to_target, pred, robot, 0.0) == 1           # node 2 wins when clear
    clear[:3] = False                                             # nothing within source_radius_m is clear ...
    assert planning._source(cfg, Sel, arrays, to_target, pred, robot, 0.0) == 3           # ... the nearest clear one
    clear[:] = False                                              # no node clear: the nearest of all, as before
    assert planning._source(cfg, Sel, arrays, to_target, pred, robot, 0.0) == 1


def test_a_robot_on_a_cut_off_piece_of_the_graph_has_no_path():
    # the graph's bridges (voronoi construction step 6) join such a piece where the robot fits; the planner
    # never jumps to a node of another piece by itself, which could lie behind an obstacle
    xy, arrays = chain_graph(with_pair=True)
    to_target, pred = dijkstra(arrays, arrays.length_m, 6)

    class Sel:
        node_xy_m = xy
        node_leg_clear = np.ones(len(xy), bool)
    robot = np.array([1.05, 0.5])                                 # nearest is node 7, on the pair
    assert planning._source(planning.PlanningConfig(), Sel, arrays, to_target, pred, robot, 0.0) == -1
