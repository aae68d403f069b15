"""Subregions of the Voronoi graph by agglomerative clustering with a dynamic-aware distance.

The paper's eq. (6): ``d_dyn(n_i, n_j) = l_e d_E + l_p d_P + l_m d_M`` with

- ``d_E``: Euclidean distance between the node positions (metres),
- ``d_P``: graph shortest-path (travel) distance over ``length_m`` (metres),
- ``d_M``: motion uncertainty accumulated along that shortest path, the line integral
  ``sum_e length_m(e) * U_m(e)`` over its edges, with ``U_m(e)`` the per-edge mean motion
  uncertainty (an edge attribute, e.g. the EMA of eq. 13). Units: U_m x metres.

Nodes are clustered with ``scipy.cluster.hierarchy.linkage`` (average or complete linkage)
on ``d_dyn`` and the dendrogram is cut at ``cut_distance``. Nodes in different connected
components are never merged. A region with high U_m is "longer" inside and towards it, so it
splits from its calm neighbour, which is what DESIGN.md §5 asks subregions to do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import networkx as nx
import numpy as np
from scipy import sparse
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.sparse.csgraph import dijkstra
from scipy.spatial.distance import squareform

from dynactivegs.errors import check_config
from dynactivegs.selection.voronoi import graph_arrays



@dataclass(frozen=True, slots=True)
class SubregionConfig:
    """Weights of eq. (6) and the clustering cut."""

    l_e: float = 1.0
    """Weight of the Euclidean distance d_E (per metre)."""
    l_p: float = 1.0
    """Weight of the graph travel distance d_P (per metre)."""
    l_m: float = 1.0
    """Weight of the accumulated motion uncertainty d_M (per U_m x metre)."""
    method: Literal["average", "complete"] = "average"
    """Linkage of the agglomerative clustering."""
    cut_distance: float = 8.0
    """The dendrogram is cut at this d_dyn: clusters merged above it stay apart."""

    def __post_init__(self) -> None:
        for name in ("l_e", "l_p", "l_m"):
            check_config(getattr(self, name) >= 0.0, f"subregions.{name}", getattr(self, name), ">= 0")
        check_config(self.l_e + self.l_p > 0.0, "subregions.l_e", self.l_e, "positive where subregions.l_p is 0")
        check_config(self.method in ("average", "complete"), "subregions.method", self.method, "'average' or 'complete'")
        check_config(self.cut_distance > 0.0, "subregions.cut_distance", self.cut_distance, "> 0")


@dataclass(frozen=True, slots=True)
class Subregions:
    """Region id per graph node (ids ``0..n_regions-1``, numbered in order of their lowest node id)."""

    labels: np.ndarray            # int64 (N,), region of node i

    def __post_init__(self) -> None:
        self.labels.flags.writeable = False

    @property
    def n_regions(self) -> int:
        return int(self.labels.max()) + 1 if len(self.labels) else 0

    def region_of(self, node: int) -> int:
        return int(self.labels[node])

    def members(self, region: int) -> np.ndarray:
        """int64 (M,) node ids of a region, ascending."""
        return np.nonzero(self.labels == region)[0]

    def local_region(self, robot_node: int) -> int:
        """The robot's own (local) region: the region of the node it is at."""
        return self.region_of(robot_node)


def dyn_distance_terms(G: nx.Graph, um_attr: str = "um_mean") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three (N, N) float64 terms of eq. (6): d_E, d_P (inf across components), d_M (inf likewise).

    ``G``: nodes ``0..N-1`` with ``xy``; edges with ``length_m`` (> 0) and ``um_attr`` (missing = 0).
    d_M follows the d_P shortest-path tree from each source (pointer doubling over the
    predecessor matrix, O(N^2 log N)); it is symmetrised, since with tied paths the tree
    from i to j and from j to i may differ.
    """
    n = G.number_of_nodes()
    xy = np.stack([np.asarray(G.nodes[i]["xy"], np.float64) for i in range(n)]) if n else np.zeros((0, 2))
    d_e = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    arrays = graph_arrays(G)
    u, v, length = arrays.u, arrays.v, arrays.length_m
    um = np.array([G.edges[a, b].get(um_attr, 0.0) for a, b in zip(u, v)], np.float64)
    assert np.all(length > 0), "edge lengths must be positive"
    m = sparse.csr_matrix((np.r_[length, length], (np.r_[u, v], np.r_[v, u])), shape=(n, n))
    d_p, pred = dijkstra(m, directed=False, return_predecessors=True)
    risk = np.zeros((n, n))
    risk[u, v] = length * um
    risk[v, u] = length * um
    cols = np.broadcast_to(np.arange(n), (n, n))
    has = pred >= 0
    ptr = np.where(has, pred, cols)                    # root and unreachable point at themselves
    acc = np.where(has, risk[np.where(has, pred, 0), cols], 0.0)
    for _ in range(max(1, math.ceil(math.log2(max(n, 2)))) + 1):
        acc = acc + np.take_along_axis(acc, ptr, axis=1)
        ptr = np.take_along_axis(ptr, ptr, axis=1)
    d_m = np.where(np.isfinite(d_p), 0.5 * (acc + acc.T), np.inf)
    return d_e, d_p, d_m


def cluster_subregions(G: nx.Graph, cfg: SubregionConfig, um_attr: str = "um_mean") -> Subregions:
    """Agglomerative clustering of the graph's nodes on d_dyn (eq. 6), cut at ``cfg.cut_distance``."""
    n = G.number_of_nodes()
    if n == 0:
        return Subregions(np.zeros(0, np.int64))
    if n == 1:
        return Subregions(np.zeros(1, np.int64))
    d_e, d_p, d_m = dyn_distance_terms(G, um_attr)
    finite = np.isfinite(d_p)
    d = cfg.l_e * d_e + cfg.l_p * np.where(finite, d_p, 0.0) + cfg.l_m * np.where(finite, d_m, 0.0)
    big = 10.0 * (float(d[finite].max()) + cfg.cut_distance) + 1.0   # across components: never merged
    d = np.where(finite, d, big)
    np.fill_diagonal(d, 0.0)
    z = linkage(squareform(d, checks=False), method=cfg.method)
    raw = fcluster(z, t=cfg.cut_distance, criterion="distance")
    _, first = np.unique(raw, return_index=True)
    order = np.argsort(first)                            # regions numbered by their lowest node id
    remap = np.empty(len(order), np.int64)
    remap[order] = np.arange(len(order))
    _, inv = np.unique(raw, return_inverse=True)
    return Subregions(remap[inv].astype(np.int64))
