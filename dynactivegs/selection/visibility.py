"""Soft visibility Vis(n, x) of query voxels from candidate views, and the view gains I_s, R_m (eqs. 8-9).

Geometry proxy. The current Gaussian map's opaque surface, ``MappingOut.surface_ijk``, is
re-binned onto the fields' voxel grid (:func:`occluder_grid`): an *occluder* voxel holds at
least one surface voxel centre.

Per graph node (camera at the node's xy, ``camera_height_m`` up) the occluders within
``range_m`` are z-buffered into a low-resolution panorama: ``n_azimuth_bins`` equal azimuth
bins over 360 deg times ``n_elevation_bins`` elevation bins over the vertical field of view.
Each occluder is splatted over the bins its bounding sphere (radius ``sqrt(3)/2`` voxel)
covers, keeping the nearest distance. A query voxel x at distance r from the camera, within
range and within the vertical field of view, falling in bin b, then has

    Vis(n, x) = sigmoid((zbuf(b) - r + margin_m) / softness_m),   Vis = 1 where zbuf(b) = inf,

so voxels on or in front of the first surface are visible, voxels behind it fade out, and
unknown space (no surface in the way) counts as visible within range (DESIGN.md §5).

Candidate views are the node with ``n_yaws`` headings ``yaw_k = 2 pi k / n_yaws``. Comparing
distances along the same ray is the same test as comparing z-depths in a perspective
render from each heading, so one panorama per node serves all its yaws: a voxel is in the
horizontal field of view of yaw_k when the centre of its azimuth bin is within ``hfov / 2``
of yaw_k (the field of view is quantised to bins; the vertical one is an elevation-angle
band, which a perspective image exceeds slightly at its corners).

Gains, with voxel volume ``v``: per node and azimuth bin ``G_s(n, b) = v sum_{x in b} Vis U_s``
and ``G_m(n, b) = v sum_{x in b} Vis U_m``; then ``I_s(n, yaw_k) = sum_{b in FOV(k)} G_s(n, b)``
(eq. 8) and ``R_m(n, yaw_k)`` likewise (eq. 9), in uncertainty x m^3.

The kernel is numba-compiled; :mod:`dynactivegs.selection._reference` has a plain-loop twin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from dynactivegs.errors import check_config


@dataclass(frozen=True, slots=True)
class VisibilityConfig:
    """Candidate views and the soft visibility test."""

    n_yaws: int = 8
    """Candidate headings per node, evenly spaced from yaw 0 (+x)."""
    n_azimuth_bins: int = 72
    """Azimuth bins of the per-node panorama (a multiple of n_yaws)."""
    n_elevation_bins: int = 12
    """Elevation bins of the panorama over the vertical field of view."""
    hfov_deg: float = 90.0
    """Horizontal field of view of a candidate view (the camera's)."""
    vfov_deg: float = 60.0
    """Vertical field of view of a candidate view (the camera's)."""
    camera_height_m: float = 1.25
    """Height of the candidate camera above the floor (the camera's)."""
    range_m: float = 4.0
    """Voxels and occluders farther than this from a candidate camera are not counted."""
    margin_m: float = 0.075
    """A voxel up to this far behind the first surface still counts as (half) visible."""
    softness_m: float = 0.04
    """Width of the sigmoid that turns the depth comparison into a soft visibility."""

    def __post_init__(self) -> None:
        check_config(1 <= self.n_yaws <= 72, "visibility.n_yaws", self.n_yaws, "in [1, 72]")
        check_config(self.n_azimuth_bins >= self.n_yaws and self.n_azimuth_bins % self.n_yaws == 0,
                     "visibility.n_azimuth_bins", self.n_azimuth_bins, "a positive multiple of visibility.n_yaws")
        check_config(1 <= self.n_elevation_bins <= 256, "visibility.n_elevation_bins", self.n_elevation_bins,
                     "in [1, 256]")
        check_config(1.0 <= self.hfov_deg <= 360.0, "visibility.hfov_deg", self.hfov_deg, "in [1, 360]")
        check_config(1.0 <= self.vfov_deg < 180.0, "visibility.vfov_deg", self.vfov_deg, "in [1, 180)")
        check_config(self.camera_height_m >= 0.0, "visibility.camera_height_m", self.camera_height_m, ">= 0 m")
        check_config(self.range_m > 0.0, "visibility.range_m", self.range_m, "> 0 m")
        check_config(self.margin_m >= 0.0, "visibility.margin_m", self.margin_m, ">= 0 m")
        check_config(self.softness_m > 0.0, "visibility.softness_m", self.softness_m, "> 0 m")

    @property
    def yaws_rad(self) -> np.ndarray:
        """float64 (n_yaws,) candidate headings."""
        return 2.0 * np.pi * np.arange(self.n_yaws) / self.n_yaws

    def fov_bins(self) -> np.ndarray:
        """bool (n_yaws, n_azimuth_bins): which azimuth bins each candidate heading sees."""
        daz = 2.0 * np.pi / self.n_azimuth_bins
        centres = -np.pi + (np.arange(self.n_azimuth_bins) + 0.5) * daz
        diff = (centres[None, :] - self.yaws_rad[:, None] + np.pi) % (2.0 * np.pi) - np.pi
        return np.abs(diff) < 0.5 * math.radians(self.hfov_deg) + 1e-9


def occluder_grid(surface_ijk: np.ndarray, surface_voxel_m: float, origin_m: np.ndarray, voxel_m: float,
                  shape: tuple[int, int, int]) -> np.ndarray:
    """bool (X, Y, Z): query voxels (grid at ``origin_m``, edge ``voxel_m``) holding a surface voxel's centre.

    ``surface_ijk`` int32 (M, 3) world-aligned voxels of edge ``surface_voxel_m``; those outside the grid are dropped.
    """
    assert surface_ijk.ndim == 2 and surface_ijk.shape[1] == 3
    occ = np.zeros(shape, np.bool_)
    if len(surface_ijk) == 0 or 0 in shape:
        return occ
    centres = (surface_ijk.astype(np.float64) + 0.5) * surface_voxel_m
    idx = np.floor((centres - np.asarray(origin_m, np.float64)) / voxel_m).astype(np.int64)
    ok = np.all((idx >= 0) & (idx < np.array(shape)), axis=1)
    occ[idx[ok, 0], idx[ok, 1], idx[ok, 2]] = True
    return occ


def column_occluders(xy_m: np.ndarray, top_m: np.ndarray, wall_top_m: float, origin_m: np.ndarray, voxel_m: float,
                     shape: tuple[int, int, int]) -> np.ndarray:
    """bool (X, Y, Z): query voxels holding part of an obstacle column of the 2D occupancy grid.

    A column stands at ``xy_m`` (K, 2) from the floor (z = 0) to its top ``top_m`` (K,); one whose
    top reaches ``wall_top_m`` (the top of the height band the grid records) is a wall of unknown
    height and fills every voxel above the floor. The map's surface misses parts of walls (one too
    close to the camera returns no depth), and through those holes a view at the edge of the
    explored part kept seeing the unknown space behind the house's outer walls.
    """
    assert xy_m.ndim == 2 and xy_m.shape[1] == 2 and top_m.shape == (len(xy_m),)
    if len(xy_m) == 0 or 0 in shape:
        return np.zeros(shape, np.bool_)
    origin_m = np.asarray(origin_m, np.float64)
    ij = np.floor((xy_m - origin_m[:2]) / voxel_m).astype(np.int64)
    ok = np.all((ij >= 0) & (ij < np.array(shape[:2])), axis=1)
    top = np.full(shape[:2], -np.inf)
    np.maximum.at(top, (ij[ok, 0], ij[ok, 1]), np.where(top_m[ok] >= wall_top_m, np.inf, top_m[ok]))
    z_lo = origin_m[2] + np.arange(shape[2]) * voxel_m                       # bottom of each voxel layer
    eps = 1e-6 * voxel_m                                                      # layers that merely touch do not count
    return (z_lo + voxel_m > eps)[None, None, :] & (z_lo[None, None, :] < top[:, :, None] - eps)   # layer meets [0, top)


@numba.njit(cache=True, nogil=True)
def _bin_gains(occ, u_s, u_m, origin, voxel, cams, n_az, n_el, half_vfov, range_m, margin, soft):  # pragma: no cover
    n_nodes = cams.shape[0]
    X, Y, Z = occ.shape
    gs = np.zeros((n_nodes, n_az))
    gm = np.zeros((n_nodes, n_az))
    zb = np.empty((n_az, n_el))
    daz = 2.0 * math.pi / n_az
    del_ = 2.0 * half_vfov / n_el
    vol = voxel * voxel * voxel
    rad = 0.5 * math.sqrt(3.0) * voxel
    for n in range(n_nodes):
        cx, cy, cz = cams[n, 0], cams[n, 1], cams[n, 2]
        i0 = max(0, int(math.floor((cx - range_m - origin[0]) / voxel)))
        i1 = min(X, int(math.floor((cx + range_m - origin[0]) / voxel)) + 1)
        j0 = max(0, int(math.floor((cy - range_m - origin[1]) / voxel)))
        j1 = min(Y, int(math.floor((cy + range_m - origin[1]) / voxel)) + 1)
        k0 = max(0, int(math.floor((cz - range_m - origin[2]) / voxel)))
        k1 = min(Z, int(math.floor((cz + range_m - origin[2]) / voxel)) + 1)
        zb[:, :] = np.inf
        for i in range(i0, i1):
            dx = origin[0] + (i + 0.5) * voxel - cx
            for j in range(j0, j1):
                dy = origin[1] + (j + 0.5) * voxel - cy
                rh = math.sqrt(dx * dx + dy * dy)
                az = math.atan2(dy, dx)
                for k in range(k0, k1):
                    if not occ[i, j, k]:
                        continue
                    dz = origin[2] + (k + 0.5) * voxel - cz
                    r = math.sqrt(rh * rh + dz * dz)
                    if r > range_m or r <= 0.0:
                        continue
                    el = math.atan2(dz, rh)
                    ha = math.atan(rad / r)
                    e0 = int(math.floor((el - ha + half_vfov) / del_))
                    e1 = int(math.floor((el + ha + half_vfov) / del_))
                    if e1 < 0 or e0 >= n_el:
                        continue
                    e0 = max(e0, 0)
                    e1 = min(e1, n_el - 1)
                    a0 = int(math.floor((az - ha + math.pi) / daz))
                    a1 = int(math.floor((az + ha + math.pi) / daz))
                    if a1 - a0 >= n_az:
                        a0, a1 = 0, n_az - 1
                    for a in range(a0, a1 + 1):
                        aa = a % n_az
                        for e in range(e0, e1 + 1):
                            if r < zb[aa, e]:
                                zb[aa, e] = r
        for i in range(i0, i1):
            dx = origin[0] + (i + 0.5) * voxel - cx
            for j in range(j0, j1):
                dy = origin[1] + (j + 0.5) * voxel - cy
                rh = math.sqrt(dx * dx + dy * dy)
                a = int(math.floor((math.atan2(dy, dx) + math.pi) / daz)) % n_az
                for k in range(k0, k1):
                    dz = origin[2] + (k + 0.5) * voxel - cz
                    r = math.sqrt(rh * rh + dz * dz)
                    if r > range_m:
                        continue
                    el = math.atan2(dz, rh)
                    if el < -half_vfov or el > half_vfov:
                        continue
                    e = min(int(math.floor((el + half_vfov) / del_)), n_el - 1)
                    z = zb[a, e]
                    if z == np.inf:
                        vis = 1.0
                    else:
                        vis = 1.0 / (1.0 + math.exp(-(z - r + margin) / soft))
                    gs[n, a] += vis * u_s[i, j, k] * vol
                    gm[n, a] += vis * u_m[i, j, k] * vol
    return gs, gm


def bin_gains(cfg: VisibilityConfig, occ: np.ndarray, u_s: np.ndarray, u_m: np.ndarray, origin_m: np.ndarray,
              voxel_m: float, node_xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per node and azimuth bin, float64 (N, n_azimuth_bins) G_s and G_m (see the module docstring).

    ``occ`` bool, ``u_s``/``u_m`` float32, all (X, Y, Z) on the grid at ``origin_m`` (float64 (3,))
    with edge ``voxel_m``; ``node_xy_m`` float64 (N, 2).
    """
    assert occ.shape == u_s.shape == u_m.shape and occ.ndim == 3
    node_xy_m = np.asarray(node_xy_m, np.float64).reshape(-1, 2)
    cams = np.concatenate([node_xy_m, np.full((len(node_xy_m), 1), cfg.camera_height_m)], axis=1)
    return _bin_gains(np.ascontiguousarray(occ), np.ascontiguousarray(u_s, np.float32),
                      np.ascontiguousarray(u_m, np.float32), np.asarray(origin_m, np.float64), float(voxel_m),
                      np.ascontiguousarray(cams), cfg.n_azimuth_bins, cfg.n_elevation_bins,
                      0.5 * math.radians(cfg.vfov_deg), cfg.range_m, cfg.margin_m, cfg.softness_m)


def view_gains(cfg: VisibilityConfig, g_bins: np.ndarray) -> np.ndarray:
    """float64 (N, n_yaws): a per-bin gain (N, n_azimuth_bins) summed over each candidate heading's field of view."""
    assert g_bins.ndim == 2 and g_bins.shape[1] == cfg.n_azimuth_bins
    return g_bins @ cfg.fov_bins().T.astype(np.float64)
