"""Plainly written twins of the fast selection kernels, for the tests.

- :func:`seen_masks_reference`: instead of a grid traversal, every cell in a ray's bounding
  box is tested for a positive-length overlap with the segment (slab test). Cells that the
  segment only touches at a corner or along an edge are excluded (the fast traversal makes
  an arbitrary choice there); random float inputs hit such ties with probability zero.
"""

from __future__ import annotations

import math

import numpy as np

from dynactivegs.selection.occupancy import (FrameRays, OccupancyConfig, OccupancyGrid, apply_seen, frame_rays, let_go,
                                             obstacle_tops, people_cells)


def _overlap(x0: float, y0: float, x1: float, y1: float, j: int, i: int) -> tuple[float, float] | None:
    """The parameter range (t_lo, t_hi) in [0, 1] over which the segment (x0, y0) -> (x1, y1) lies in the
    open unit cell [j, j+1) x [i, i+1); None without a positive-length overlap."""
    t_lo, t_hi = 0.0, 1.0
    for p, d, c in ((x0, x1 - x0, j), (y0, y1 - y0, i)):
        if d == 0.0:
            if not (c < p < c + 1):
                return None
            continue
        ta, tb = (c - p) / d, (c + 1 - p) / d
        t_lo, t_hi = max(t_lo, min(ta, tb)), min(t_hi, max(ta, tb))
    return (t_lo, t_hi) if t_lo < t_hi else None


def seen_masks_reference(shape: tuple[int, int], rays: FrameRays, top_m: np.ndarray,
                         clear_below_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Reference of :func:`dynactivegs.selection.occupancy.seen_masks`."""
    h, w = shape
    seen_free = np.zeros(shape, bool)
    seen_occ = np.zeros(shape, bool)
    x0, y0 = float(rays.start_g[0]), float(rays.start_g[1])
    z0 = float(rays.start_z_m)
    for k in range(len(rays.end_g)):
        x1, y1 = float(rays.end_g[k, 0]), float(rays.end_g[k, 1])
        z1 = float(rays.end_z_m[k])
        ei, ej = math.floor(y1), math.floor(x1)
        if rays.end_occupied[k] and 0 <= ei < h and 0 <= ej < w:
            seen_occ[ei, ej] = True
        for i in range(math.floor(min(y0, y1)), math.floor(max(y0, y1)) + 1):
            for j in range(math.floor(min(x0, x1)), math.floor(max(x0, x1)) + 1):
                if not (0 <= i < h and 0 <= j < w):
                    continue
                if (i, j) == (ei, ej):
                    seen_free[i, j] |= bool(rays.end_free[k])
                    continue
                span = _overlap(x0, y0, x1, y1, j, i)
                if span is not None and (top_m[i, j] <= 0.0
                                         or min(z0 + t * (z1 - z0) for t in span) < max(top_m[i, j], clear_below_m)):
                    seen_free[i, j] = True
    ci, cj = math.floor(y0), math.floor(x0)
    if 0 <= ci < h and 0 <= cj < w:
        seen_free[ci, cj] = True
    return seen_free, seen_occ


def update_occupancy_reference(grid: OccupancyGrid, cfg: OccupancyConfig, depth_m: np.ndarray, K: np.ndarray,
                               T_world_cam: np.ndarray, beta: np.ndarray) -> OccupancyGrid:
    """Reference of :func:`dynactivegs.selection.occupancy.update_occupancy`."""
    grid, rays = frame_rays(grid, cfg, depth_m, K, T_world_cam, beta)
    top = obstacle_tops(grid.top_m, rays)
    seen_free, seen_occ = seen_masks_reference(grid.shape, rays, top, cfg.clear_below_m)
    return let_go(grid, cfg, apply_seen(grid.logodds, seen_free, seen_occ, cfg), top, seen_occ,
                  people_cells(grid.shape, rays))


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


def view_gain_reference(cfg, occ: np.ndarray, u_s: np.ndarray, u_m: np.ndarray, origin_m: np.ndarray, voxel_m: float,
                        xy_m: tuple[float, float], yaw_rad: float) -> tuple[float, float]:
    """Reference of :mod:`dynactivegs.selection.visibility` for one candidate view: (I_s, R_m) of eqs. (8)-(9).

    Loops over every voxel of the grid: first every occluder (its bounding-sphere footprint
    in panorama bins, nearest distance kept), then every query voxel (in range, in the
    vertical field of view, azimuth bin centre within hfov / 2 of ``yaw_rad``).
    """
    X, Y, Z = occ.shape
    n_az, n_el = cfg.n_azimuth_bins, cfg.n_elevation_bins
    hv = 0.5 * math.radians(cfg.vfov_deg)
    daz, de = 2 * math.pi / n_az, 2 * hv / n_el
    cam = (float(xy_m[0]), float(xy_m[1]), cfg.camera_height_m)
    centre = lambda i, j, k: tuple(float(origin_m[a]) + (idx + 0.5) * voxel_m for a, idx in enumerate((i, j, k)))
    zbuf = {}
    for i in range(X):
        for j in range(Y):
            for k in range(Z):
                if not occ[i, j, k]:
                    continue
                d = [c - p for c, p in zip(centre(i, j, k), cam)]
                rh = math.sqrt(d[0] ** 2 + d[1] ** 2)
                r = math.sqrt(rh ** 2 + d[2] ** 2)
                if r > cfg.range_m or r <= 0:
                    continue
                ha = math.atan(0.5 * math.sqrt(3) * voxel_m / r)
                az, el = math.atan2(d[1], d[0]), math.atan2(d[2], rh)
                a_lo, a_hi = math.floor((az - ha + math.pi) / daz), math.floor((az + ha + math.pi) / daz)
                bins_a = range(n_az) if a_hi - a_lo >= n_az else [a % n_az for a in range(a_lo, a_hi + 1)]
                for a in bins_a:
                    for e in range(n_el):
                        if math.floor((el - ha + hv) / de) <= e <= math.floor((el + ha + hv) / de):
                            zbuf[(a, e)] = min(zbuf.get((a, e), math.inf), r)
    gain = risk = 0.0
    for i in range(X):
        for j in range(Y):
            for k in range(Z):
                d = [c - p for c, p in zip(centre(i, j, k), cam)]
                rh = math.sqrt(d[0] ** 2 + d[1] ** 2)
                r = math.sqrt(rh ** 2 + d[2] ** 2)
                el = math.atan2(d[2], rh)
                if r > cfg.range_m or abs(el) > hv:
                    continue
                a = math.floor((math.atan2(d[1], d[0]) + math.pi) / daz) % n_az
                bin_centre = -math.pi + (a + 0.5) * daz
                if abs((bin_centre - yaw_rad + math.pi) % (2 * math.pi) - math.pi) >= 0.5 * math.radians(cfg.hfov_deg) + 1e-9:
                    continue
                e = min(math.floor((el + hv) / de), n_el - 1)
                z = zbuf.get((a, e), math.inf)
                vis = 1.0 if z == math.inf else 1.0 / (1.0 + math.exp(-(z - r + cfg.margin_m) / cfg.softness_m))
                gain += vis * float(u_s[i, j, k]) * voxel_m ** 3
                risk += vis * float(u_m[i, j, k]) * voxel_m ** 3
    return gain, risk
