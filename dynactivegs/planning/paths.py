"""Motion-aware shortest paths on the Voronoi graph.

- Edge cost, the paper's eq. (11): ``c(e) = len(e) + l_m * mean U_m along e``.
- Temporal averaging of the per-edge motion uncertainty, eq. (13):
  ``U_m(e)_t = (1 - gamma) U_m(e)_{t-1} + gamma * mean U_m along e at t``, kept in an
  explicit per-edge state array and updated by a pure function.
- Planner variants (the paper's Table 5): ``shortest`` (c = len), ``dyn_edge`` (eq. 11 with
  the current U_m), ``dyn_edge_temporal`` (eq. 11 with the EMA of eq. 13).
- Dijkstra on a CSR matrix (scipy.sparse.csgraph), with a networkx twin in
  :mod:`dynactivegs.planning._reference`.

Graphs are those of :mod:`dynactivegs.selection.voronoi`: nodes ``0..N-1``, edge attributes
``length_m`` and ``cells`` (the pixel chain used for the line integrals of U_m). Per-edge
arrays follow the order of :class:`GraphArrays` (edges sorted by ``(u, v)`` with ``u < v``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import networkx as nx
import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra as _cs_dijkstra

from dynactivegs.errors import check_config
from dynactivegs.selection.voronoi import GraphArrays, graph_arrays  # noqa: F401 (re-exported)

PlannerVariant = Literal["shortest", "dyn_edge", "dyn_edge_temporal"]
PLANNER_VARIANTS: tuple[str, ...] = get_args(PlannerVariant)



@dataclass(frozen=True, slots=True)
class PathConfig:
    """Edge costs and the planner variant."""

    variant: PlannerVariant = "dyn_edge_temporal"
    """Which edge cost: shortest (length only), dyn_edge (eq. 11, current U_m) or dyn_edge_temporal (eq. 11, EMA of eq. 13).
    The cost can only change the path where the graph offers another way round. On the apartment scenes it
    rarely does: over the 12 runs of each of baseline, weighted, motion_view and full in
    benchmarks/results/apartment-1000-crowd (path_stats.md, columns detour % and loops) the selection's graph
    had 0.65-0.86 independent cycles on the mean over a 1000-step run, per preset (at most 1.9 in a run), and
    full's path was more than 5 % longer than the shortest on 1.3 % of its steps (8.7 % in one run), the
    shortest-cost presets' (their detours from blocked spots' penalties) on 0.5-0.8 %. On the loop suite
    (benchmarks/results/loop-1000, a door in every shared wall, seeds 0-1) the graph has 2.7 cycles and full's path
    is a detour on 3.3 % of its steps, and full scores 0.27 +- 0.61 dB more PSNR than the shortest planner
    (motion_view), higher in 7 of 8 pairs, with as many hold-ups."""
    motion_weight: float = 4.0
    """l_m of eq. (11): metres of detour worth one unit of mean motion uncertainty along an edge."""
    ema_gamma: float = 0.2
    """gamma of eq. (13): weight of the current step in the per-edge EMA of U_m (1 = no memory)."""

    def __post_init__(self) -> None:
        check_config(self.variant in PLANNER_VARIANTS, "planning.variant", self.variant, f"one of {PLANNER_VARIANTS}")
        check_config(self.motion_weight >= 0.0, "planning.motion_weight", self.motion_weight, ">= 0")
        check_config(0.0 < self.ema_gamma <= 1.0, "planning.ema_gamma", self.ema_gamma, "in (0, 1]")


def edge_mean_along(arrays: GraphArrays, value_map: np.ndarray) -> np.ndarray:
    """float64 (E,): mean of ``value_map`` (H, W) over each edge's cells (the discrete line integral / length).

    Edges without cells get 0. Cells outside the map count as 0.
    """
    assert value_map.ndim == 2
    counts = np.diff(arrays.cell_start)
    h, w = value_map.shape
    c = arrays.cells
    ok = (c[:, 0] >= 0) & (c[:, 0] < h) & (c[:, 1] >= 0) & (c[:, 1] < w)
    vals = np.zeros(len(c), np.float64)
    vals[ok] = value_map[c[ok, 0], c[ok, 1]]
    edge_of = np.repeat(np.arange(arrays.n_edges), counts)
    sums = np.bincount(edge_of, weights=vals, minlength=arrays.n_edges)
    return np.where(counts > 0, sums / np.maximum(counts, 1), 0.0)


def edge_cost(length_m: np.ndarray, motion_unc: np.ndarray, motion_weight: float) -> np.ndarray:
    """Traversal cost of graph edges: c(e) = len(e) + lambda_m * mean U_m along e (eq. 11)."""
    assert length_m.shape == motion_unc.shape
    return length_m + motion_weight * motion_unc


def ema_update(um_ema: np.ndarray, um_now: np.ndarray, gamma: float) -> np.ndarray:
    """Per-edge temporal average of the motion uncertainty (eq. 13): (1 - gamma) * um_ema + gamma * um_now.

    Both float64 (E,), same edge order. Returns a new array.
    """
    assert um_ema.shape == um_now.shape
    return (1.0 - gamma) * um_ema + gamma * um_now


def variant_edge_cost(cfg: PathConfig, length_m: np.ndarray, um_now: np.ndarray, um_ema: np.ndarray) -> np.ndarray:
    """float64 (E,) edge costs of the configured planner variant (Table 5 of the paper)."""
    if cfg.variant == "shortest":
        return length_m.astype(np.float64, copy=True)
    if cfg.variant == "dyn_edge":
        return edge_cost(length_m, um_now, cfg.motion_weight)
    return edge_cost(length_m, um_ema, cfg.motion_weight)


def transfer_edge_values(old: GraphArrays, old_values: np.ndarray, new: GraphArrays, shape: tuple[int, int],
                         default: float = 0.0) -> np.ndarray:
    """Carry a per-edge quantity (e.g. the eq. 13 EMA) over to a rebuilt graph.

    Old values are painted onto their edges' cells (averaged where edges share a cell); each
    new edge takes the mean over its cells that carry a value, or ``default`` if none does.
    ``shape``: (H, W) of the grid both graphs' cells index (grow the old cells' offsets first
    if the grid's origin moved).
    """
    assert old_values.shape == (old.n_edges,)
    acc = np.zeros(shape, np.float64)
    cnt = np.zeros(shape, np.int64)
    counts = np.diff(old.cell_start)
    per_cell = np.repeat(old_values.astype(np.float64), counts)
    h, w = shape
    c = old.cells
    ok = (c[:, 0] >= 0) & (c[:, 0] < h) & (c[:, 1] >= 0) & (c[:, 1] < w)
    np.add.at(acc, (c[ok, 0], c[ok, 1]), per_cell[ok])
    np.add.at(cnt, (c[ok, 0], c[ok, 1]), 1)
    mean_map = np.divide(acc, cnt, out=np.zeros(shape), where=cnt > 0)
    has = (cnt > 0).astype(np.float64)
    num = edge_mean_along(new, mean_map)
    frac = edge_mean_along(new, has)
    return np.where(frac > 0, num / np.where(frac > 0, frac, 1.0), default)


def cost_matrix(arrays: GraphArrays, cost: np.ndarray) -> sparse.csr_matrix:
    """Symmetric (N, N) CSR matrix of edge costs. Costs must be positive (csgraph drops zero entries)."""
    assert cost.shape == (arrays.n_edges,)
    assert np.all(cost > 0) and np.all(np.isfinite(cost)), "edge costs must be positive and finite"
    n = arrays.n_nodes
    return sparse.csr_matrix((np.r_[cost, cost], (np.r_[arrays.u, arrays.v], np.r_[arrays.v, arrays.u])), shape=(n, n))


def dijkstra(arrays: GraphArrays, cost: np.ndarray, source: int) -> tuple[np.ndarray, np.ndarray]:
    """Costs (N,) float64 from ``source`` to every node (inf if unreachable) and predecessors (N,) int (-9999 at source/unreachable)."""
    dist, pred = _cs_dijkstra(cost_matrix(arrays, cost), directed=False, indices=source, return_predecessors=True)
    return dist, pred


def shortest_path(arrays: GraphArrays, cost: np.ndarray, source: int, target: int) -> tuple[list[int], float]:
    """Cheapest node path source -> target and its cost; ``([], inf)`` if unreachable."""
    assert 0 <= source < arrays.n_nodes and 0 <= target < arrays.n_nodes
    dist, pred = dijkstra(arrays, cost, source)
    if not np.isfinite(dist[target]):
        return [], float("inf")
    path = [target]
    while path[-1] != source:
        path.append(int(pred[path[-1]]))
    return path[::-1], float(dist[target])


def path_polyline(G: nx.Graph, nodes: list[int]) -> np.ndarray:
    """float64 (K, 2) world xy along the edges' cell chains of a node path (node positions included, no repeats).

    Uses ``G.graph['cell_m']`` and ``G.graph['origin_xy_m']``. A single-node path gives its position.
    """
    if not nodes:
        return np.zeros((0, 2))
    cell_m = G.graph["cell_m"]
    origin = np.asarray(G.graph["origin_xy_m"], np.float64)
    out = [np.asarray(G.nodes[nodes[0]]["xy"], np.float64)[None]]
    for a, b in zip(nodes[:-1], nodes[1:]):
        c = np.asarray(G.edges[a, b]["cells"])
        if a > b:
            c = c[::-1]
        out.append(origin + (c[1:, ::-1].astype(np.float64) + 0.5) * cell_m)
    return np.concatenate(out)


def thin_polyline(xy: np.ndarray, spacing_m: float) -> np.ndarray:
    """Every point of ``xy (K, 2)`` at least ``spacing_m`` of path length after the previous kept one; the last is kept."""
    if len(xy) <= 2:
        return xy.copy()
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    keep = [0]
    for k in range(1, len(xy) - 1):
        if s[k] - s[keep[-1]] >= spacing_m:
            keep.append(k)
    keep.append(len(xy) - 1)
    return xy[keep]
