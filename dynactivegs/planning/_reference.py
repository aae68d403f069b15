"""Plainly written twins of the fast planning kernels, for the tests."""

from __future__ import annotations

import networkx as nx
import numpy as np

from dynactivegs.planning.paths import GraphArrays


def shortest_path_reference(arrays: GraphArrays, cost: np.ndarray, source: int, target: int) -> tuple[list[int], float]:
    """Reference of :func:`dynactivegs.planning.paths.shortest_path`: networkx.dijkstra_path on a fresh graph."""
    G = nx.Graph()
    G.add_nodes_from(range(arrays.n_nodes))
    for a, b, c in zip(arrays.u.tolist(), arrays.v.tolist(), cost.tolist()):
        G.add_edge(a, b, cost=c)
    try:
        path = nx.dijkstra_path(G, source, target, weight="cost")
    except nx.NetworkXNoPath:
        return [], float("inf")
    return path, float(sum(G.edges[a, b]["cost"] for a, b in zip(path[:-1], path[1:])))


def edge_mean_along_reference(G: nx.Graph, value_map: np.ndarray) -> dict[tuple[int, int], float]:
    """Reference of :func:`dynactivegs.planning.paths.edge_mean_along`, keyed by (u, v) with u < v."""
    out = {}
    h, w = value_map.shape
    for a, b, d in G.edges(data=True):
        vals = [float(value_map[i, j]) if 0 <= i < h and 0 <= j < w else 0.0 for i, j in d["cells"]]
        out[(min(a, b), max(a, b))] = sum(vals) / len(vals) if vals else 0.0
    return out
