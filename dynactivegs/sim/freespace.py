"""The navigable 2D map at robot height, computed from the static mesh.

Used by the simulator for spawning and collision, by the crowd for path following, and by
the evaluation. Never by the planner: the planner only knows what the robot has seen.

Grid convention: cell ``(i, j)`` (row ``i`` along +y, column ``j`` along +x) covers
``[x0 + j r, x0 + (j+1) r) x [y0 + i r, y0 + (i+1) r)`` where ``(x0, y0) = origin_xy_m`` and
``r = res_m``; its centre is at ``origin + (j + 0.5, i + 0.5) r``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np
from scipy import ndimage, sparse
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class FreeSpace:
    """Occupancy of the floor plane: where there is floor, and where obstacles stand."""

    origin_xy_m: np.ndarray       # float64 (2,), world xy of the grid's lower-left corner
    res_m: float                  # cell size
    floor: np.ndarray             # bool (H, W), a walkable floor surface exists under the cell
    occupied: np.ndarray          # bool (H, W), some static surface lies in the body's height band
    obstacle_xy_m: np.ndarray | None = None
    """float32 (N, 2) points on obstacle surfaces (from a mesh); when given, clearance to obstacles is
    measured to these points instead of to the occupied cells' boundaries (which is conservative by up
    to one cell)."""
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        assert self.floor.shape == self.occupied.shape and self.floor.ndim == 2
        assert self.origin_xy_m.shape == (2,)
        self.floor.flags.writeable = False
        self.occupied.flags.writeable = False

    @staticmethod
    def from_grid(occupied: np.ndarray, res_m: float, origin_xy_m=(0.0, 0.0),
                  floor: np.ndarray | None = None) -> "FreeSpace":
        """A map from a hand-made occupancy array (floor everywhere unless given)."""
        occupied = np.asarray(occupied, dtype=bool).copy()
        floor = np.ones_like(occupied) if floor is None else np.asarray(floor, dtype=bool).copy()
        return FreeSpace(np.asarray(origin_xy_m, dtype=np.float64), float(res_m), floor, occupied)

    @property
    def shape(self) -> tuple[int, int]:
        return self.floor.shape  # type: ignore[return-value]

    # ------------------------------------------------------------------ coordinates
    def world_to_cell(self, xy_m: np.ndarray) -> np.ndarray:
        """Integer cell indices ``(..., 2)`` as (row, col) for world points ``(..., 2)``; may be out of range."""
        xy_m = np.asarray(xy_m, dtype=np.float64)
        ij = np.floor((xy_m - self.origin_xy_m) / self.res_m).astype(np.int64)
        return ij[..., ::-1]

    def cell_to_world(self, ij: np.ndarray) -> np.ndarray:
        """World xy ``(..., 2)`` of the centres of cells ``(..., 2)`` given as (row, col)."""
        ij = np.asarray(ij)
        return self.origin_xy_m + (ij[..., ::-1].astype(np.float64) + 0.5) * self.res_m

    def in_bounds(self, ij: np.ndarray) -> np.ndarray:
        h, w = self.shape
        return (ij[..., 0] >= 0) & (ij[..., 0] < h) & (ij[..., 1] >= 0) & (ij[..., 1] < w)

    # ------------------------------------------------------------------ derived maps
    @property
    def blocked(self) -> np.ndarray:
        """Cells a body centre can never occupy: no floor, or an obstacle."""
        return self._cached("blocked", lambda: ~self.floor | self.occupied)

    @property
    def clearance_m(self) -> np.ndarray:
        """float64 (H, W): distance from each cell centre to the nearest blocked cell's boundary (0 inside)."""
        def compute() -> np.ndarray:
            walls = self.blocked if self.obstacle_xy_m is None else ~self.floor
            padded = np.pad(~walls, 1, constant_values=False)  # outside the grid is blocked
            d = np.maximum(ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * self.res_m - 0.5 * self.res_m, 0.0)
            if self.obstacle_xy_m is not None and len(self.obstacle_xy_m):
                free = np.argwhere(~self.blocked)
                dist, _ = cKDTree(self.obstacle_xy_m).query(self.cell_to_world(free), workers=-1)
                d[free[:, 0], free[:, 1]] = np.minimum(d[free[:, 0], free[:, 1]], dist)
            return np.where(self.blocked, 0.0, d)
        return self._cached("clearance", compute)

    def navigable(self, radius_m: float) -> np.ndarray:
        """bool (H, W): cells where a disc of ``radius_m`` fits, restricted to the largest connected component."""
        def compute() -> np.ndarray:
            ok = ~self.blocked & (self.clearance_m >= radius_m)
            labels, n = ndimage.label(ok)
            if n == 0:
                return ok
            sizes = np.bincount(labels.ravel())
            sizes[0] = 0
            return labels == int(np.argmax(sizes))
        return self._cached(("navigable", round(radius_m, 6)), compute)

    def free_area_m2(self) -> float:
        """Area of floor not covered by obstacles, in the largest connected region."""
        return float(self.navigable(0.0).sum()) * self.res_m ** 2

    def is_navigable(self, xy_m: np.ndarray, radius_m: float) -> np.ndarray:
        """bool (...): whether discs of ``radius_m`` centred at ``xy_m (..., 2)`` fit in free space."""
        ij = self.world_to_cell(xy_m)
        ok = self.in_bounds(ij)
        nav = self.navigable(radius_m)
        h, w = self.shape
        out = np.zeros(ij.shape[:-1], dtype=bool)
        out[ok] = nav[np.clip(ij[..., 0], 0, h - 1), np.clip(ij[..., 1], 0, w - 1)][ok]
        return out

    def segment_navigable(self, a_xy_m: np.ndarray, b_xy_m: np.ndarray, radius_m: float) -> bool:
        """Whether a disc of ``radius_m`` can slide along the segment a -> b without leaving free space."""
        a = np.asarray(a_xy_m, dtype=np.float64)
        b = np.asarray(b_xy_m, dtype=np.float64)
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / (0.5 * self.res_m))) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return bool(self.is_navigable(a + t * (b - a), radius_m).all())

    def obstacle_points_xy(self) -> np.ndarray:
        """float64 (N, 2): centres of blocked cells that touch a non-blocked cell (the obstacle boundary)."""
        def compute() -> np.ndarray:
            inner = ndimage.binary_erosion(self.blocked, structure=np.ones((3, 3), bool), border_value=True)
            edge = self.blocked & ~inner
            return self.cell_to_world(np.argwhere(edge))
        return self._cached("obstacle_points", compute)

    def sample_navigable(self, rng: np.random.Generator, n: int, radius_m: float) -> np.ndarray:
        """float64 (n, 2): centres of uniformly random cells where a disc of ``radius_m`` fits."""
        cells = np.argwhere(self.navigable(radius_m))
        if len(cells) == 0:
            raise ValueError(f"no navigable cell for radius {radius_m} m")
        pick = cells[rng.integers(0, len(cells), size=n)]
        return self.cell_to_world(pick)

    def _cached(self, key, compute):
        if key not in self._cache:
            value = compute()
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            self._cache[key] = value
        return self._cache[key]


def _segment_points(a: np.ndarray, b: np.ndarray, spacing: float) -> np.ndarray:
    """Points every ``spacing`` (or closer) along segments a -> b, both (N, 2); endpoints included."""
    if len(a) == 0:
        return np.zeros((0, 2))
    n = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / spacing).astype(np.int64), 1) + 1
    seg = np.repeat(np.arange(len(a)), n)
    start = np.repeat(np.cumsum(n) - n, n)
    t = (np.arange(n.sum()) - start) / np.repeat(n - 1, n)
    return a[seg] + t[:, None] * (b[seg] - a[seg])


def _triangle_points(tri_xy: np.ndarray, spacing: float) -> np.ndarray:
    """Points on a regular barycentric lattice of each triangle (T, 3, 2), at most ``spacing`` apart."""
    if len(tri_xy) == 0:
        return np.zeros((0, 2))
    edges = np.linalg.norm(tri_xy[:, [1, 2, 0]] - tri_xy, axis=2).max(axis=1)
    n = np.maximum(np.ceil(edges / spacing).astype(np.int64), 1)
    out = []
    for k in np.unique(n):
        sel = tri_xy[n == k]
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = (i + j) <= k
        w1 = (i[keep] / k)[None, :, None]
        w2 = (j[keep] / k)[None, :, None]
        p0, p1, p2 = sel[:, None, 0], sel[:, None, 1], sel[:, None, 2]
        out.append((p0 + w1 * (p1 - p0) + w2 * (p2 - p0)).reshape(-1, 2))
    return np.concatenate(out)


def freespace_from_mesh(triangles_m: np.ndarray, cast_down, *, res_m: float = 0.05, band_lo_m: float = 0.1,
                        band_hi_m: float = 1.5, slice_step_m: float = 0.05) -> FreeSpace:
    """Free space of a static mesh at robot height.

    - ``floor``: a downward ray from ``band_lo_m`` above the cell centre finds a surface within
      0.25 m (so cells outside the building, with nothing underneath, are not floor).
    - ``occupied``: some surface lies between ``band_lo_m`` and ``band_hi_m`` above the floor.
      Non-horizontal surfaces are found by slicing the mesh with horizontal planes every
      ``slice_step_m``; surfaces thinner than the slice step inside the band (table tops, seats)
      are rasterized from their xy projection.

    ``triangles_m``: float64 (F, 3, 3), world frame, floor at z = 0. ``cast_down(origins (N, 3))``
    returns the hit distance of rays cast straight down (inf on miss).
    """
    assert triangles_m.ndim == 3 and triangles_m.shape[1:] == (3, 3)
    lo = triangles_m.reshape(-1, 3)[:, :2].min(axis=0) - 2 * res_m
    hi = triangles_m.reshape(-1, 3)[:, :2].max(axis=0) + 2 * res_m
    w, h = np.ceil((hi - lo) / res_m).astype(int)
    origin = np.floor(lo / res_m) * res_m
    fs_empty = FreeSpace(origin, res_m, np.zeros((h, w), bool), np.zeros((h, w), bool))

    # Floor: downward rays from the band's lower edge.
    centres = fs_empty.cell_to_world(np.argwhere(np.ones((h, w), bool)))
    t = cast_down(np.c_[centres, np.full(len(centres), band_lo_m)])
    floor = (t <= band_lo_m + 0.15).reshape(h, w)

    # Occupancy: slices through the band, plus thin surfaces inside it.
    z = triangles_m[:, :, 2]
    zmin, zmax = z.min(axis=1), z.max(axis=1)
    in_band = (zmax >= band_lo_m) & (zmin <= band_hi_m)
    tri = triangles_m[in_band]
    z, zmin, zmax = z[in_band], zmin[in_band], zmax[in_band]
    pts = []
    heights = np.arange(band_lo_m, band_hi_m + 1e-9, slice_step_m)
    for hz in heights:
        cross = (zmin < hz) & (zmax > hz)
        if not cross.any():
            continue
        tc, zc = tri[cross], z[cross]
        above = zc > hz
        # each crossing triangle has exactly two edges with a sign change
        ends = []
        for e0, e1 in ((0, 1), (1, 2), (2, 0)):
            ch = above[:, e0] != above[:, e1]
            s = (hz - zc[:, e0]) / np.where(ch, zc[:, e1] - zc[:, e0], 1.0)
            ends.append((ch, tc[:, e0, :2] + s[:, None] * (tc[:, e1, :2] - tc[:, e0, :2])))
        ch = np.stack([e[0] for e in ends], axis=1)
        p = np.stack([e[1] for e in ends], axis=1)
        first = np.argmax(ch, axis=1)
        second = 2 - np.argmax(ch[:, ::-1], axis=1)
        rows = np.arange(len(tc))
        pts.append(_segment_points(p[rows, first], p[rows, second], 0.5 * res_m))
    thin = (np.minimum(zmax, band_hi_m) - np.maximum(zmin, band_lo_m)) < slice_step_m
    pts.append(_triangle_points(tri[thin][:, :, :2], 0.5 * res_m))
    pts_all = np.concatenate(pts) if pts else np.zeros((0, 2))
    occupied = np.zeros((h, w), bool)
    ij = fs_empty.world_to_cell(pts_all)
    ok = fs_empty.in_bounds(ij)
    occupied[ij[ok, 0], ij[ok, 1]] = True
    q = np.round((pts_all - origin) / 0.01).astype(np.int64)   # deduplicate on a 1 cm lattice
    key = np.unique(q[:, 0] * (1 << 31) + q[:, 1])
    obstacle_xy = (np.stack([key >> 31, key & ((1 << 31) - 1)], axis=1) * 0.01 + origin).astype(np.float32)
    return FreeSpace(origin, res_m, floor, occupied, obstacle_xy)


def grid_graph(mask: np.ndarray, cell_m: float) -> tuple[sparse.csr_matrix, np.ndarray]:
    """8-connected graph over the True cells of ``mask`` (H, W), without cutting corners.

    Returns the symmetric adjacency matrix (n, n) with edge lengths in metres, and the cells
    (n, 2) as (row, col): node k is cell ``cells[k]`` (row-major order). A diagonal edge exists
    only when both cells it passes between are True, so paths never squeeze between two
    blocked cells that touch at a corner.
    """
    assert mask.ndim == 2 and mask.dtype == np.bool_
    h, w = mask.shape
    ids = -np.ones((h, w), np.int64)
    ids[mask] = np.arange(int(mask.sum()))
    rows, cols, wts = [], [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        j0, j1 = max(0, -dj), w - max(0, dj)          # columns of the first cell of each pair
        ok = mask[:h - di, j0:j1] & mask[di:, j0 + dj:j1 + dj]
        if di and dj:
            ok &= mask[di:, j0:j1] & mask[:h - di, j0 + dj:j1 + dj]
        a = ids[:h - di, j0:j1][ok]
        b = ids[di:, j0 + dj:j1 + dj][ok]
        length = np.full(len(a), math.hypot(di, dj) * cell_m)
        rows += [a, b]
        cols += [b, a]
        wts += [length, length]
    n = int(mask.sum())
    graph = sparse.csr_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return graph, np.argwhere(mask)
