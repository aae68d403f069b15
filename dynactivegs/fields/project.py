"""U_m of a :class:`~dynactivegs.records.FieldsOut` as a 2D floor map, for subregions (eq. 6) and edge costs (eq. 11).

The floor map has one cell per (x, y) voxel column of the fields grid; its value is the
largest U_m among the column's voxels whose centres lie in the height band where people
are (``[z_lo_m, z_hi_m]``): a person seen anywhere in that band makes the floor cell busy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynactivegs.records import FieldsOut


@dataclass(frozen=True, slots=True)
class FloorMap:
    """A value per floor cell: cell (i, j) covers ``origin_xy_m + [i, i+1) x [j, j+1) * cell_m`` (x first)."""

    origin_xy_m: np.ndarray       # float64 (2,)
    cell_m: float
    values: np.ndarray            # float64 (X, Y)

    def __post_init__(self) -> None:
        assert self.origin_xy_m.shape == (2,) and self.values.ndim == 2

    def sample(self, xy_m: np.ndarray) -> np.ndarray:
        """float64 (...,) values at world points ``xy_m (..., 2)`` (the cell containing each); 0 outside the map."""
        xy = np.asarray(xy_m, np.float64)
        flat = xy.reshape(-1, 2)
        ij = np.floor((flat - self.origin_xy_m) / self.cell_m).astype(np.int64)
        X, Y = self.values.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < X) & (ij[:, 1] >= 0) & (ij[:, 1] < Y)
        out = np.zeros(len(flat), np.float64)
        out[ok] = self.values[ij[ok, 0], ij[ok, 1]]
        out = out.reshape(xy.shape[:-1])
        return out


def motion_floor_map(fields: FieldsOut, z_lo_m: float, z_hi_m: float) -> FloorMap:
    """U_m projected to the floor: the column maximum over voxel centres with z in ``[z_lo_m, z_hi_m]``."""
    X, Y, Z = fields.u_m.shape
    zc = fields.origin_m[2] + (np.arange(Z) + 0.5) * fields.voxel_m
    band = (zc >= z_lo_m) & (zc <= z_hi_m)
    if X == 0 or Y == 0 or not band.any():
        values = np.zeros((X, Y), np.float64)
    else:
        values = fields.u_m[:, :, band].max(axis=2).astype(np.float64)
    return FloorMap(fields.origin_m[:2].copy(), float(fields.voxel_m), values)


def segment_means(fmap: FloorMap, a_xy_m: np.ndarray, b_xy_m: np.ndarray, spacing_m: float) -> np.ndarray:
    """float64 (E,): mean of the map along each straight segment a -> b (samples about ``spacing_m`` apart, ends included)."""
    a = np.asarray(a_xy_m, np.float64).reshape(-1, 2)
    b = np.asarray(b_xy_m, np.float64).reshape(-1, 2)
    assert a.shape == b.shape
    if len(a) == 0:
        return np.zeros(0)
    n = np.maximum(2, np.ceil(np.hypot(*(b - a).T) / spacing_m).astype(np.int64) + 1)
    seg = np.repeat(np.arange(len(a)), n)
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    t = (np.arange(n.sum()) - np.repeat(start, n)) / np.repeat(n - 1, n)
    pts = a[seg] + t[:, None] * (b[seg] - a[seg])
    vals = fmap.sample(pts)
    return np.bincount(seg, weights=vals, minlength=len(a)) / n
