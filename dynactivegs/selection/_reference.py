"""Plainly written twins of the fast selection kernels, for the tests.

- :func:`seen_masks_reference`: instead of a grid traversal, every cell in a ray's bounding
  box is tested for a positive-length overlap with the segment (slab test). Cells that the
  segment only touches at a corner or along an edge are excluded (the fast traversal makes
  an arbitrary choice there); random float inputs hit such ties with probability zero.
"""

from __future__ import annotations

import math

import numpy as np

from dynactivegs.selection.occupancy import FrameRays, OccupancyConfig, OccupancyGrid, apply_seen, frame_rays


def _overlaps(x0: float, y0: float, x1: float, y1: float, j: int, i: int) -> bool:
    """Whether the segment (x0, y0) -> (x1, y1) overlaps the open unit cell [j, j+1) x [i, i+1) over t in [0, 1]."""
    t_lo, t_hi = 0.0, 1.0
    for p, d, c in ((x0, x1 - x0, j), (y0, y1 - y0, i)):
        if d == 0.0:
            if not (c < p < c + 1):
                return False
            continue
        ta, tb = (c - p) / d, (c + 1 - p) / d
        t_lo, t_hi = max(t_lo, min(ta, tb)), min(t_hi, max(ta, tb))
    return t_lo < t_hi


def seen_masks_reference(shape: tuple[int, int], rays: FrameRays) -> tuple[np.ndarray, np.ndarray]:
    """Reference of :func:`dynactivegs.selection.occupancy.seen_masks`."""
    h, w = shape
    seen_free = np.zeros(shape, bool)
    seen_occ = np.zeros(shape, bool)
    x0, y0 = float(rays.start_g[0]), float(rays.start_g[1])
    for k in range(len(rays.end_g)):
        x1, y1 = float(rays.end_g[k, 0]), float(rays.end_g[k, 1])
        ei, ej = math.floor(y1), math.floor(x1)
        for i in range(math.floor(min(y0, y1)), math.floor(max(y0, y1)) + 1):
            for j in range(math.floor(min(x0, x1)), math.floor(max(x0, x1)) + 1):
                if (i, j) == (ei, ej) and not rays.end_free[k]:
                    continue
                if 0 <= i < h and 0 <= j < w and _overlaps(x0, y0, x1, y1, j, i):
                    seen_free[i, j] = True
        if rays.end_occupied[k] and 0 <= ei < h and 0 <= ej < w:
            seen_occ[ei, ej] = True
    ci, cj = math.floor(y0), math.floor(x0)
    if 0 <= ci < h and 0 <= cj < w:
        seen_free[ci, cj] = True
    return seen_free, seen_occ


def update_occupancy_reference(grid: OccupancyGrid, cfg: OccupancyConfig, depth_m: np.ndarray, K: np.ndarray,
                               T_world_cam: np.ndarray, beta: np.ndarray) -> OccupancyGrid:
    """Reference of :func:`dynactivegs.selection.occupancy.update_occupancy`."""
    grid, rays = frame_rays(grid, cfg, depth_m, K, T_world_cam, beta)
    seen_free, seen_occ = seen_masks_reference(grid.shape, rays)
    return OccupancyGrid(grid.origin_ij, grid.cell_m, apply_seen(grid.logodds, seen_free, seen_occ, cfg))


def dyn_distance_terms_reference(G, um_attr: str = "um_mean") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference of :func:`dynactivegs.selection.subregions.dyn_distance_terms`: one networkx path per pair.

    With tied shortest paths the two may pick different paths; the tests use random lengths.
    """
    import networkx as nx

    n = G.number_of_nodes()
    d_e = np.zeros((n, n))
    d_p = np.full((n, n), np.inf)
    d_m = np.full((n, n), np.inf)
    for i in range(n):
        paths = nx.single_source_dijkstra_path(G, i, weight="length_m")
        for j in range(n):
            d_e[i, j] = math.dist(G.nodes[i]["xy"], G.nodes[j]["xy"])
            if j in paths:
                p = paths[j]
                d_p[i, j] = sum(G.edges[a, b]["length_m"] for a, b in zip(p[:-1], p[1:]))
                d_m[i, j] = sum(G.edges[a, b]["length_m"] * G.edges[a, b].get(um_attr, 0.0) for a, b in zip(p[:-1], p[1:]))
    return d_e, d_p, d_m
