"""Voronoi graph on hand-made occupancy maps: line, junction, loop, no wall crossing, pruning, frontiers."""

from __future__ import annotations

import dataclasses
import math

import networkx as nx
import numpy as np
import pytest

from dynactivegs.errors import ConfigError
from dynactivegs.selection.occupancy import OccupancyConfig, OccupancyGrid
from dynactivegs.selection.voronoi import (
    VoronoiConfig, build_voronoi_graph, graph_arrays, graph_from_occupancy, nearest_node, node_xy, traversable_mask,
)

CELL = 0.05
CFG = VoronoiConfig(robot_radius_m=0.18, node_spacing_m=0.75, min_spur_m=0.5, frontier_dist_m=0.8)
ORIGIN = np.array([-1.0, 2.0])


def box(free: np.ndarray, x0: float, y0: float, x1: float, y1: float, value: bool = True) -> None:
    """Set the cells whose centres lie in [x0, x1] x [y0, y1] (metres, map frame without origin)."""
    h, w = free.shape
    xs = (np.arange(w) + 0.5) * CELL
    ys = (np.arange(h) + 0.5) * CELL
    free[np.ix_((ys >= y0) & (ys <= y1), (xs >= x0) & (xs <= x1))] = value


def world(x: float, y: float) -> np.ndarray:
    return ORIGIN + np.array([x, y])


def build(free: np.ndarray, unknown: np.ndarray | None = None, cfg: VoronoiConfig = CFG) -> nx.Graph:
    unknown = np.zeros_like(free) if unknown is None else unknown
    return build_voronoi_graph(free, unknown, CELL, ORIGIN, cfg)


def corridor() -> np.ndarray:
    free = np.zeros((40, 140), bool)
    box(free, 0.5, 0.5, 6.5, 1.5)             # a 6 m x 1 m corridor
    return free


def assert_never_crosses_obstacles(G: nx.Graph, free: np.ndarray) -> None:
    trav = traversable_mask(free, CELL, CFG.robot_radius_m)
    for u, v, d in G.edges(data=True):
        c = d["cells"]
        assert trav[c[:, 0], c[:, 1]].all(), f"edge {u}-{v} leaves the traversable space"
        assert c[0].tolist() == list(G.nodes[min(u, v)]["cell"]) and c[-1].tolist() == list(G.nodes[max(u, v)]["cell"])
        step = np.abs(np.diff(c, axis=0)).max()
        assert step <= 2                       # a chain of neighbours (at most a hop inside a junction blob)
        poly = np.hypot(*np.diff(c.astype(float), axis=0).T).sum() * CELL
        assert d["length_m"] == pytest.approx(poly)


def test_corridor_gives_a_line_along_its_middle():
    free = corridor()
    G = build(free)
    assert nx.is_connected(G) and nx.is_tree(G)
    assert max(dict(G.degree).values()) <= 2
    xy = node_xy(G) - ORIGIN
    span = xy[:, 0].max() - xy[:, 0].min()
    assert span > 4.5
    middle = (xy[:, 0] > 1.2) & (xy[:, 0] < 5.8)
    assert np.abs(xy[middle, 1] - 1.0).max() <= 0.05
    total = sum(d["length_m"] for _, _, d in G.edges(data=True))
    assert max(d["length_m"] for _, _, d in G.edges(data=True)) <= 1.5 * CFG.node_spacing_m
    assert G.number_of_nodes() >= total / (1.5 * CFG.node_spacing_m)
    assert_never_crosses_obstacles(G, free)
    assert not any(nx.get_node_attributes(G, "frontier").values())   # a closed corridor has no frontier


def test_t_gives_one_junction_of_degree_three():
    free = np.zeros((80, 140), bool)
    box(free, 0.5, 2.5, 6.5, 3.5)               # a corridor along x
    box(free, 3.0, 0.5, 4.0, 2.5)               # a branch going down from its middle
    G = build(free)
    deg = dict(G.degree)
    junctions = [n for n, d in deg.items() if d == 3]
    assert len(junctions) == 1 and max(deg.values()) == 3
    j = G.nodes[junctions[0]]["xy"] - ORIGIN
    assert abs(j[0] - 3.5) < 0.2 and abs(j[1] - 3.0) < 0.6
    assert G.nodes[junctions[0]]["kind"] == "junction"
    assert nx.is_connected(G) and nx.is_tree(G)
    assert_never_crosses_obstacles(G, free)


def test_room_with_a_pillar_gives_a_loop_around_it():
    free = np.zeros((120, 120), bool)
    box(free, 0.5, 0.5, 5.5, 5.5)
    box(free, 2.5, 2.5, 3.5, 3.5, False)        # 1 m pillar in the middle
    G = build(free)
    assert_never_crosses_obstacles(G, free)
    cycles = nx.cycle_basis(G)
    assert cycles
    pillar = world(3.0, 3.0)

    def winding(cycle: list[int]) -> float:
        pts = np.array([G.nodes[n]["xy"] for n in cycle]) - pillar
        ang = np.arctan2(pts[:, 1], pts[:, 0])
        return float(np.sum((np.diff(np.r_[ang, ang[0]]) + math.pi) % (2 * math.pi) - math.pi))

    assert any(abs(abs(winding(c)) - 2 * math.pi) < 1e-6 for c in cycles)
    # without the pillar the room's skeleton has no loop
    free2 = np.zeros((120, 120), bool)
    box(free2, 0.5, 0.5, 5.5, 5.5)
    assert not nx.cycle_basis(build(free2))


def test_short_spurs_are_pruned_long_ones_kept():
    free = corridor()
    box(free, 3.0, 1.4, 3.6, 1.75)              # a shallow niche: its skeleton spur is short
    G0 = build(free, cfg=VoronoiConfig(robot_radius_m=0.18, min_spur_m=0.0))
    assert max(dict(G0.degree).values()) >= 3   # the unpruned skeleton does branch into the niche
    G = build(free)
    assert max(dict(G.degree).values()) <= 2 and nx.is_tree(G)
    # a deep side passage (1.5 m) is a real branch
    deep = np.zeros((80, 140), bool)
    deep[:40] = corridor()
    box(deep, 3.0, 1.4, 4.0, 3.0)
    assert max(dict(build(deep).degree).values()) == 3


def test_frontier_nodes_where_the_map_borders_unknown_space():
    free = corridor()
    unknown = np.zeros_like(free)
    box(free, 6.4, 0.55, 6.6, 1.45, False)      # the corridor's right end is not seen yet
    box(unknown, 6.4, 0.55, 6.6, 1.45)
    box(free, 6.5, 0.5, 6.6, 1.5, False)
    G = build(free, unknown)
    xy = node_xy(G) - ORIGIN
    fr = np.array([G.nodes[i]["frontier"] for i in range(len(xy))])
    assert fr.any()
    assert xy[fr, 0].min() > 5.5               # only near the open end
    assert not fr[xy[:, 0] < 5.0].any()


def test_graph_from_occupancy_grid_and_nearest_node_and_determinism():
    free = corridor()
    occ_cfg = OccupancyConfig(cell_m=CELL)
    logodds = np.where(free, -1.0, 1.0).astype(np.float32)
    grid = OccupancyGrid((40, -20), CELL, logodds)
    G = graph_from_occupancy(grid, occ_cfg, CFG)
    G2 = graph_from_occupancy(grid, occ_cfg, CFG)
    assert G.number_of_nodes() > 5 and sorted(G.edges) == sorted(G2.edges)
    assert all(np.array_equal(G.nodes[n]["xy"], G2.nodes[n]["xy"]) for n in G)
    n = nearest_node(G, grid.origin_xy_m + np.array([3.0, 1.0]))
    assert np.linalg.norm(G.nodes[n]["xy"] - grid.origin_xy_m - [3.0, 1.0]) < 0.5
    assert nearest_node(build(np.zeros((5, 5), bool)), np.zeros(2)) == -1


def test_bad_config_raises():
    with pytest.raises(ConfigError):
        VoronoiConfig(node_spacing_m=0.0)
    with pytest.raises(ConfigError):
        VoronoiConfig(robot_radius_m=-1.0)


def test_a_speck_of_unknown_floor_inside_the_room_is_not_a_frontier():
    free = corridor()
    unknown = np.zeros_like(free)
    free[20, 60] = False                         # one unseen cell between sparse rays
    unknown[20, 60] = True
    G = build(free, unknown)
    assert not any(nx.get_node_attributes(G, "frontier").values())
    G_all = build(free, unknown, VoronoiConfig(min_frontier_m=0.0))
    assert any(nx.get_node_attributes(G_all, "frontier").values())


def test_selection_and_planning_import_without_torch():
    import subprocess
    import sys
    code = ("import sys; import dynactivegs.selection.occupancy, dynactivegs.selection.voronoi, "
            "dynactivegs.selection.subregions, dynactivegs.planning.paths, dynactivegs.planning.actions; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def room_and_pocket(gap_m: float) -> np.ndarray:
    """A 3.3 m x 1 m corridor and a 0.6 m x 1.2 m pocket at its end, joined by a 0.3 m long passage ``gap_m`` wide:
    narrower than the skeleton's clearance (0.44 m), so the pocket's skeleton is a piece of its own."""
    free = np.zeros((60, 120), bool)
    box(free, 0.2, 1.0, 3.5, 2.0)                 # the corridor
    box(free, 3.8, 0.9, 4.4, 2.1)                 # the pocket
    box(free, 3.5, 1.5 - gap_m / 2 + 0.01, 3.8, 1.5 + gap_m / 2 - 0.01)   # the passage
    return free


def test_a_tiny_piece_is_bridged_to_a_larger_one_where_the_robot_fits_the_gap():
    free = room_and_pocket(0.40)
    assert nx.number_connected_components(build(free, cfg=dataclasses.replace(CFG, bridge_min_nodes=1))) == 2
    G = build(free)
    assert nx.is_connected(G)
    bridges = [(u, v, d) for u, v, d in G.edges(data=True) if d.get("bridge")]
    assert len(bridges) == 1
    u, v, d = bridges[0]
    xs = sorted(float(G.nodes[n]["xy"][0] - ORIGIN[0]) for n in (u, v))
    assert xs[0] < 3.5 and xs[1] > 3.8                        # from the corridor into the pocket
    c = d["cells"]
    assert free[c[:, 0], c[:, 1]].all()
    assert c[0].tolist() == list(G.nodes[u]["cell"]) and c[-1].tolist() == list(G.nodes[v]["cell"])
    assert np.abs(np.diff(c, axis=0)).max() == 1                 # a chain of 8-neighbours
    assert d["length_m"] == pytest.approx(np.hypot(*np.diff(c.astype(float), axis=0).T).sum() * CELL)
    assert float(np.hypot(*(G.nodes[u]["xy"] - G.nodes[v]["xy"]))) <= d["length_m"] <= CFG.bridge_length_m
    assert graph_arrays(G).n_edges == G.number_of_edges()


def test_no_bridge_through_a_gap_too_narrow_or_unknown():
    assert nx.number_connected_components(build(room_and_pocket(0.30))) == 2       # the robot's disc does not fit
    free = room_and_pocket(0.40)
    unknown = np.zeros_like(free)
    box(unknown, 3.6, 1.2, 3.7, 1.8)                          # a strip of the passage the camera never saw
    free &= ~unknown
    assert nx.number_connected_components(build(free, unknown)) == 2
